"""The CMM error model: instrument file, sources, their distributions and displacements."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.instruments.cmm import (
    SOURCE_NAMES,
    CmmInstrument,
    draw_bound,
    load_instrument,
    point_displacements,
    point_error_sources,
    reference_paper_instrument,
)
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.montecarlo.distributions import Normal, Rectangular

SHIPPED = Path(__file__).resolve().parents[2] / "config" / "instruments" / "cmm_reference_paper.yaml"
SEED_KEYS = {
    "mpe_a_um": 1.2,
    "mpe_k_mm_per_um": 350,
    "thermal_expansion_half_width_per_degc": 2.0e-6,
    "temperature_deviation_degc": 0.3,
    "probing_half_width_um": 2.0,
    "algorithm_half_width_um": 0.05,
}


def write_yaml(tmp_path: Path, entries: dict[str, object]) -> Path:
    path = tmp_path / "cmm.yaml"
    path.write_text("".join(f"{k}: {v}\n" for k, v in entries.items()), encoding="utf-8")
    return path


def test_shipped_instrument_is_the_seeds() -> None:
    loaded = load_instrument(SHIPPED)
    seed = reference_paper_instrument()
    for field in ("mpe_a", "mpe_k", "thermal_half_width", "temperature_deviation"):
        assert getattr(loaded, field) == pytest.approx(getattr(seed, field), rel=1e-12)
    assert loaded.probing_half_width == pytest.approx(2e-6, rel=1e-12)
    assert loaded.algorithm_half_width == pytest.approx(0.05e-6, rel=1e-12)
    assert loaded.name.startswith("reference_paper_cmm")


def test_mpe_formula() -> None:
    # E = 1.2 + L/350 µm with L in mm: 2.2 µm at 350 mm, 1.2 µm at the reference point.
    assert CmmInstrument().mpe([0.0, 0.35]) == pytest.approx([1.2e-6, 2.2e-6], rel=1e-12)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"mpe_a_um": "'a lot'"}, "mpe_a_um must be a number"),
        ({"mpe_k_mm_per_um": 0}, "mpe_k must be > 0"),
        ({"probing_half_width_um": -1}, "probing_half_width must be >= 0"),
        ({"mpe_a_mm": 1.0}, r"unknown keys \['mpe_a_mm'\]"),
        ({"temperature_deviation_degc": None}, "must be a number"),
    ],
)
def test_instrument_file_errors(tmp_path: Path, change: dict[str, object], match: str) -> None:
    entries: dict[str, object] = {**SEED_KEYS, **change}
    with pytest.raises(ConfigError, match=match) as info:
        load_instrument(write_yaml(tmp_path, entries))
    assert "\n" not in str(info.value)


def test_instrument_file_structure_errors(tmp_path: Path) -> None:
    entries = dict(SEED_KEYS)
    del entries["mpe_a_um"]
    with pytest.raises(ConfigError, match=r"missing keys \['mpe_a_um'\]"):
        load_instrument(write_yaml(tmp_path, entries))
    bad = tmp_path / "bad.yaml"
    bad.write_text("mpe_a_um: [1,\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_instrument(bad)
    bad.write_text("- 1\n- 2\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="must hold a mapping"):
        load_instrument(bad)
    with pytest.raises(ConfigError, match="cannot read instrument file"):
        load_instrument(tmp_path / "absent.yaml")
    with pytest.raises(ConfigError, match="mpe_a must be a finite number"):
        CmmInstrument(mpe_a=float("nan"))


def geometry() -> tuple[np.ndarray, np.ndarray]:
    points = np.array([[0.0, 0.0], [0.1, 0.0], [0.3, 0.4]])
    normals = np.array([[0.0, 1.0], [1.0, 0.0], [0.6, 0.8]])
    return points, normals


def test_sources_follow_the_seed_model() -> None:
    points, normals = geometry()
    probes = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    mpe, thermal, probing, algorithm = point_error_sources(
        CmmInstrument(), points, normals, reference=(0.0, 0.0), probe_vectors=probes
    )
    assert tuple(s.name for s in (mpe, thermal, probing, algorithm)) == SOURCE_NAMES
    # MPE half-width 1.2 + L/350 µm at L = 0, 100 and 500 mm, two draws per point.
    assert mpe.gain == pytest.approx([1.2e-6, (1.2 + 100 / 350) * 1e-6, (1.2 + 500 / 350) * 1e-6])
    assert mpe.n_draws == 6 and draw_bound(mpe.distribution) == 1.0
    # Thermal: one δα per trial; a length L changes by δα Δt L, so u = 1.15e-3 L Δt µm (L in mm).
    assert thermal.n_draws == 1
    u_length = thermal.draw_uncertainty * np.linalg.norm(thermal.gain[2])
    assert u_length == pytest.approx(1.1547e-3 * 500 * 0.3 * 1e-6, rel=1e-4)
    # Probing along the probe vectors' in-plane part, algorithm along the normals.
    assert probing.gain == pytest.approx(probes[:, :2])
    assert probing.draw_uncertainty == pytest.approx(2e-6 / np.sqrt(3))
    assert algorithm.gain == pytest.approx(normals)
    assert algorithm.draw_uncertainty == pytest.approx(0.05e-6 / np.sqrt(3))


def test_probing_acts_along_the_normals_without_probe_vectors() -> None:
    points, normals = geometry()
    probing = point_error_sources(CmmInstrument(), points, normals, reference=(0.0, 0.0))[2]
    assert probing.gain == pytest.approx(normals)


def test_displacements_are_linear_in_the_draws() -> None:
    points, normals = geometry()
    sources = point_error_sources(CmmInstrument(), points, normals, reference=(0.0, 0.0))
    rng = np.random.default_rng(5)
    index = np.arange(3)
    for source in sources:
        draws = source.draw(rng, 4)
        assert draws.shape == (4, source.n_draws)
        shift = source.displacement(draws, index)
        assert shift.shape == (4, 3, 2)
        along = source.normal_displacement(draws, normals)
        assert along == pytest.approx(np.einsum("tij,ij->ti", shift, normals), abs=1e-18)
    total = point_displacements(sources, np.random.default_rng(1), 2)
    assert total.shape == (2, 3, 2)
    assert np.abs(total).max() < 6e-6


def test_zero_magnitude_source_draws_zeros_and_bounds() -> None:
    points, normals = geometry()
    quiet = CmmInstrument(probing_half_width=0.0)
    probing = point_error_sources(quiet, points, normals, reference=(0.0, 0.0))[2]
    assert not probing.draw(np.random.default_rng(0), 3).any()
    assert draw_bound(Rectangular(-2.0, 1.0)) == 2.0
    assert draw_bound(Normal(0.0, 1.0)) == pytest.approx(6.0)


def test_source_input_errors() -> None:
    points, normals = geometry()
    with pytest.raises(InputError, match="normals must have shape"):
        point_error_sources(CmmInstrument(), points, normals[:2], reference=(0.0, 0.0))
    with pytest.raises(InputError, match="reference must be a finite"):
        point_error_sources(CmmInstrument(), points, normals, reference=(np.nan, 0.0))
    with pytest.raises(InputError, match="probe_vectors must have shape"):
        point_error_sources(CmmInstrument(), points, normals, reference=(0.0, 0.0), probe_vectors=np.ones((3, 4)))
