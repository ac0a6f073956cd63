"""Sources that draw sub-batch by sub-batch give the block's draws bit for bit.

A trial block lets a source whose ``draws_by_rows`` is True draw each sub-batch's rows when
it applies them, instead of the whole block first: the random streams must not change.
"""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.montecarlo.distributions import (
    CorrelatedNormal,
    Empirical,
    IndependentCopies,
    IndependentNormal,
    IndependentRectangular,
    Normal,
    Rectangular,
)
from robocal_uncertainty.uncertainty.sources import AdditiveSource

ROW_DRAWN = [
    IndependentRectangular(np.array([1e-5, 2e-5, 0.0, 3e-5]), np.array([0.0, 1.0, 0.0, -2.0])),
    IndependentNormal(np.array([1e-4, 0.0, 2e-4, 1.0]), np.array([0.5, 0.0, 0.0, 1.0])),
    IndependentCopies(Rectangular(-2e-5, 3e-5), 4),
    IndependentCopies(Normal(0.1, 2e-3), 4),
]


def _source(dist: object) -> AdditiveSource:
    return AdditiveSource("s", dist, (("points", (dist.size,)),))  # type: ignore[arg-type, attr-defined]


@pytest.mark.parametrize("dist", ROW_DRAWN, ids=lambda d: type(d).__name__)
def test_row_drawn_sources_give_the_block_draws_in_pieces(dist: object) -> None:
    source = _source(dist)
    assert source.draws_by_rows
    whole = source.draw(np.random.default_rng(7), 1000)
    rng = np.random.default_rng(7)
    pieces = np.concatenate([source.draw(rng, t) for t in (256, 256, 1, 255, 232)])
    np.testing.assert_array_equal(pieces, whole)


@pytest.mark.parametrize(
    "dist",
    [
        IndependentCopies(Empirical(np.arange(12.0).reshape(4, 3)), 3),
        CorrelatedNormal(np.zeros(2), np.array([[1.0, 0.3], [0.3, 2.0]])),
    ],
    ids=["Empirical", "CorrelatedNormal"],
)
def test_integer_and_matrix_draws_are_drawn_by_the_block(dist: object) -> None:
    # Integers come from a buffered 32-bit stream and a matrix product may round by the row
    # count: these are drawn for the whole block at once.
    assert not _source(dist).draws_by_rows
