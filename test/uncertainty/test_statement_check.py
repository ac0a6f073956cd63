"""The checks that decide whether a Monte Carlo run is a statement at all."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from robocal_uncertainty.report.table2 import _budget_cell
from robocal_uncertainty.uncertainty.statement_check import (
    GUM_DISAGREEMENT_FACTOR,
    gum_disagreements,
    interval_trial_floor,
    recommended_trials,
    too_few_trials_note,
)


def _pose(mc: list[float], gum: list[float], mean: float = 1.0) -> SimpleNamespace:
    return SimpleNamespace(
        axes=tuple(SimpleNamespace(standard_uncertainty=u) for u in mc),
        mean=np.full(3, mean),
        gum=SimpleNamespace(standard_uncertainty=np.array(gum)),
    )


def test_trial_counts_follow_the_coverage_probability() -> None:
    # 2/(1-p): one trial beyond each end of a probabilistically symmetric interval.
    assert interval_trial_floor(0.95) == 40 and interval_trial_floor(0.99) == 200 and interval_trial_floor(0.5) == 4
    assert recommended_trials(0.95) == 2000 and recommended_trials(0.99) == 10000
    assert too_few_trials_note(2000, 0.95) is None
    note = too_few_trials_note(400, 0.95)
    assert note is not None and "its ends rest on 10 trials each" in note and "--trials 2000" in note


def test_the_guard_fires_beyond_the_factor_either_way_and_only_there() -> None:
    f = GUM_DISAGREEMENT_FACTOR
    assert gum_disagreements([_pose([1e-4, 2e-4, 3e-4], [1e-4, 2e-4, 3e-4])]) == ()
    assert gum_disagreements([_pose([0.99 * f * 1e-4, 1e-4, 1e-4], [1e-4] * 3)]) == ()
    assert gum_disagreements([_pose([1e-4, 1e-4, 1e-4 / (0.99 * f)], [1e-4] * 3)]) == ()
    (line,) = gum_disagreements([_pose([1e-4, 1.01 * f * 1e-4, 1e-4], [1e-4] * 3)])
    assert (
        line.startswith("test configuration 1: Monte Carlo u = 1.01 mm against its first-order (GUM) u = 0.1 mm")
        and "along y" in line
    )
    (line,) = gum_disagreements([_pose([1e-4, 1e-4, 1e-6], [1e-4] * 3)])
    assert "along z (ratio 0.01" in line
    # No GUM value (no smooth source): nothing to compare, nothing refused.
    assert gum_disagreements([_pose([1.0, 1.0, 1.0], [0.0, 0.0, 0.0])]) == ()
    (line,) = gum_disagreements([_pose([np.inf, 1e-4, 1e-4], [1e-4] * 3)])
    assert "non-finite" in line


@pytest.mark.parametrize(("value", "text"), [(4.0e-9, "< 0.001"), (0.0, "0"), (0.0042, "0.0042"), (23.4, "23")])
def test_budget_cells_below_a_nanometre_are_not_printed_as_digits(value: float, text: str) -> None:
    assert _budget_cell(value) == text
