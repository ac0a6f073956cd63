"""The reference paper's CMM is shipped as ``cmm_reference_paper``; the old name ``cmm_seed`` (read
like the random seed) is still accepted, with a warning, and gives the same instrument."""

from __future__ import annotations

import pytest

from robocal_uncertainty.app.section_inspection import resolve_instrument
from robocal_uncertainty.core.instruments.cmm import CmmInstrument, reference_paper_instrument
from robocal_uncertainty.errors import ConfigError


def test_shipped_file_holds_the_reference_papers_magnitudes() -> None:
    # The paper's §1.2: MPE 1.2 + L/350 µm, 2e-6 /°C at 0.3 °C, probing 2 µm, algorithm 0.05 µm.
    shipped, where = resolve_instrument(None)
    assert where == "cmm_reference_paper"
    paper = reference_paper_instrument()
    assert (shipped.mpe_a, shipped.mpe_k) == pytest.approx((1.2e-6, 350.0), rel=1e-12)
    assert (shipped.thermal_half_width, shipped.temperature_deviation) == pytest.approx((2e-6, 0.3), rel=1e-12)
    assert (shipped.probing_half_width, shipped.algorithm_half_width) == pytest.approx((2e-6, 0.05e-6), rel=1e-12)
    assert shipped.mpe_a == paper.mpe_a and shipped.algorithm_half_width == paper.algorithm_half_width
    assert shipped.name.startswith("reference_paper_cmm")
    assert isinstance(shipped, CmmInstrument)


def test_old_name_is_accepted_with_a_deprecation_warning() -> None:
    with pytest.warns(DeprecationWarning, match="cmm_seed"):
        old, where = resolve_instrument("cmm_seed")
    assert where == "cmm_reference_paper"
    new = resolve_instrument("cmm_reference_paper")[0]
    assert (old.mpe_a, old.mpe_k, old.probing_half_width) == (new.mpe_a, new.mpe_k, new.probing_half_width)
    assert old.name == new.name


def test_unknown_name_is_refused_with_the_shipped_names() -> None:
    with pytest.raises(ConfigError, match="cmm_reference_paper"):
        resolve_instrument("cmm_nonexistent")
