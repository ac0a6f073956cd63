"""The blade-section trial on the numba backend gives the numpy backend's trials, from the same draws.

The compiled trial sums the same products in loops (and factors each edge window's hat matrix,
6m operations instead of m²), so it agrees with the numpy frozen model to rounding, not bit
for bit: the bar is 1e-12 relative to the largest value of each parameter over the trials.
Checked on whole trial blocks for the edge windows grown per trial (a 0.3° twist makes the
extreme points and the window sizes vary) and frozen, both methods, a source subset in another
order, a source of zero magnitude, a source the kernel cannot draw itself (numpy's draws then),
numba without ``Generator`` support (the same), the GUM budget's columns, and the statements
of :func:`~robocal_uncertainty.inspection.section_mc.section_uncertainty`.
"""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core.instruments.cmm import SOURCE_NAMES, CmmInstrument
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import PointCloud, read_rotor37_section
from robocal_uncertainty.inspection.section_mc import SectionTrials, TrialSetup, prepare_trials, section_uncertainty
from robocal_uncertainty.inspection.simulate import simulate_section_scan
from robocal_uncertainty.kernels import NumbaBackend, available_backends, section_kernels
from robocal_uncertainty.kernels.section_kernels import resolve_section_backend
from robocal_uncertainty.montecarlo.distributions import Normal
from robocal_uncertainty.montecarlo.engine import run_trials

ROTOR37 = Path(__file__).resolve().parents[1] / "inspection" / "data" / "nasa_rotor37_blade_geometry.dat"
ROTOR37_SCALE = 7.14

HAS_NUMBA = NumbaBackend().available()
needs_numba = pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed (extra 'fast')")
RTOL = 1e-12
OFFSET = (-0.1013e-3, 0.0538e-3)


@pytest.fixture(scope="module")
def curve() -> NominalCurve:
    return NominalCurve(read_rotor37_section(ROTOR37, 2, scale=ROTOR37_SCALE))


@pytest.fixture(scope="module")
def twisted(curve: NominalCurve) -> PointCloud:
    """1 836 points, twist 0.3°: both edges' extreme points vary per trial, with uncertain window sizes."""
    return simulate_section_scan(curve, 1836, offset=OFFSET, twist=np.deg2rad(0.3), form_amplitude=5e-6)


@pytest.fixture(scope="module")
def twisted_setup(twisted: PointCloud, curve: NominalCurve) -> TrialSetup:
    return prepare_trials(twisted, curve)


@pytest.fixture(scope="module")
def small(curve: NominalCurve) -> PointCloud:
    return simulate_section_scan(curve, 400, offset=OFFSET, twist=np.deg2rad(0.0512), form_amplitude=5e-6)


def _close(numba_values: np.ndarray, numpy_values: np.ndarray) -> None:
    """Equal to 1e-12 of each column's largest magnitude (a parameter near zero, e.g. an offset,
    carries the absolute round-off of the larger terms it is summed from)."""
    scale = np.abs(numpy_values).max(axis=0)
    assert numba_values.shape == numpy_values.shape
    assert (np.abs(numba_values - numpy_values) <= RTOL * scale).all()


def _both(block: SectionTrials, n: int = 300, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    numpy_values = np.asarray(run_trials(block, seed=seed, n_trials=n, block_size=128).samples)
    compiled = dataclasses.replace(block, backend="numba")
    numba_values = np.asarray(run_trials(compiled, seed=seed, n_trials=n, block_size=128).samples)
    return numba_values, numpy_values


def test_backend_names_for_the_section_trial(monkeypatch: pytest.MonkeyPatch) -> None:
    expected = "numba" if "numba" in available_backends() else "numpy"
    assert resolve_section_backend("auto").name == expected
    assert resolve_section_backend("auto").requested == "auto"
    assert resolve_section_backend("numpy").version == np.__version__
    with pytest.raises(ConfigError, match="'cupy' has no blade-section kernel"):
        resolve_section_backend("cupy")
    with pytest.raises(ConfigError, match="backend must be one of"):
        resolve_section_backend("fortran")
    monkeypatch.setattr(NumbaBackend, "available", lambda self: False)
    assert resolve_section_backend("auto").name == "numpy"
    with pytest.raises(ConfigError, match="not available here"):
        resolve_section_backend("numba")


@needs_numba
@pytest.mark.parametrize("method", ["denoised", "perturbed"])
def test_grown_edge_windows_equal_numpy(
    twisted: PointCloud, twisted_setup: TrialSetup, curve: NominalCurve, method: str
) -> None:
    setup = twisted_setup if method == "denoised" else prepare_trials(twisted, curve, method=method)
    block = setup.trials(batch=100)
    edges = block.model.edges
    assert edges is not None and any(any(checks) for edge in edges for checks in edge.checks)
    # The kernel draws its values itself where numba compiles Generators (>= 0.56); Humble's 0.55
    # takes numpy's draws batch by batch: the values must be equal either way.
    assert dataclasses.replace(block, backend="numba").kernel.fused == section_kernels._generators_supported()
    numba_values, numpy_values = _both(block)
    _close(numba_values, numpy_values)
    # The trials really vary the leading edge's extreme point and window.
    assert np.unique(numpy_values[:, 5]).size > 100


@needs_numba
def test_frozen_edges_source_subset_and_zero_source_equal_numpy(small: PointCloud, curve: NominalCurve) -> None:
    # Probing off (zero magnitude, a point mass the kernel skips), the subset in another order.
    instrument = CmmInstrument(probing_half_width=0.0)
    setup = prepare_trials(small, curve, instrument=instrument, sources=("probing", "algorithm", "mpe"))
    block = setup.trials(batch=50, resegment_edges=False)
    assert block.model.edges is None and isinstance(block.sources[0].distribution, Normal)
    assert block.source_indices == tuple(SOURCE_NAMES.index(n) for n in ("probing", "algorithm", "mpe"))
    numba_values, numpy_values = _both(block)
    _close(numba_values, numpy_values)


@needs_numba
def test_numpy_draws_when_the_kernel_cannot_draw(
    small: PointCloud, curve: NominalCurve, monkeypatch: pytest.MonkeyPatch
) -> None:
    block = prepare_trials(small, curve).trials(batch=64)
    # A normal (not rectangular) source: the kernel takes numpy's draws batch by batch.
    thermal = dataclasses.replace(block.sources[1], distribution=Normal(0.0, 1e-6))
    normal_block = dataclasses.replace(block, sources=(block.sources[0], thermal, *block.sources[2:]))
    assert not dataclasses.replace(normal_block, backend="numba").kernel.fused
    _close(*_both(normal_block))
    # numba without Generator support (Humble's 0.55): the same.
    monkeypatch.setattr(section_kernels, "_generators_supported", lambda: False)
    assert not dataclasses.replace(block, backend="numba").kernel.fused
    _close(*_both(block))


@needs_numba
def test_given_draws_and_pickling(twisted_setup: TrialSetup) -> None:
    block = twisted_setup.trials()
    compiled = dataclasses.replace(block, backend="numba")
    rng = np.random.default_rng(3)
    draws = [source.draw(rng, 40) for source in block.sources]
    _close(compiled.evaluate_draws(draws), block.evaluate_draws(draws))
    copy = pickle.loads(pickle.dumps(compiled))  # as sent to a worker process
    assert np.array_equal(copy.evaluate_draws(draws), compiled.evaluate_draws(draws))


@needs_numba
def test_section_uncertainty_records_the_backend_and_states_the_same(small: PointCloud, curve: NominalCurve) -> None:
    runs = {
        name: section_uncertainty(small, curve, seed=4, trials=2000, block_size=500, backend=name)
        for name in ("numpy", "numba")
    }
    assert runs["numba"].backend is not None and runs["numba"].backend.name == "numba"
    assert runs["numpy"].backend is not None and runs["numpy"].backend.describe() == f"numpy {np.__version__}"
    for a, b in zip(runs["numba"].monte_carlo.outputs, runs["numpy"].monte_carlo.outputs):
        scale = max(abs(b.estimate), b.standard_uncertainty)
        assert abs(a.estimate - b.estimate) <= RTOL * scale
        assert a.standard_uncertainty == pytest.approx(b.standard_uncertainty, rel=1e-9)
    _close(runs["numba"].gum.sensitivities, runs["numpy"].gum.sensitivities)


@needs_numba
@pytest.mark.skipif(not section_kernels._generators_supported(), reason="numba < 0.56 compiles no Generator")
def test_inline_pcg64_draws_equal_the_generators_bit_for_bit(twisted_setup: TrialSetup) -> None:
    from robocal_uncertainty.kernels import section_numba

    kernel = dataclasses.replace(twisted_setup.trials(), backend="numba").kernel
    sources = len(kernel.sources)

    def generators() -> list[np.random.Generator]:
        return [np.random.default_rng(np.random.SeedSequence(11, spawn_key=(4, k))) for k in range(sources)]

    through_generators = generators()
    padding = [np.random.default_rng(0)] * (4 - sources)
    expected = np.empty((57, 9))
    section_numba.fused_trials((*through_generators, *padding), kernel.packed, expected)
    inline = generators()
    values = kernel.trials(inline, 57, 16)  # PCG64 streams: the kernel steps their states itself
    assert np.array_equal(values, expected)
    # Each generator continues where the kernel stopped, as after numba's own draws.
    for a, b in zip(inline, through_generators):
        assert a.bit_generator.state == b.bit_generator.state
        assert np.array_equal(a.random(5), b.random(5))
    # Another bit generator: the kernel draws through the Generator, the same values.
    other = [np.random.Generator(np.random.Philox(k)) for k in range(sources)]
    reference = [np.random.Generator(np.random.Philox(k)) for k in range(sources)]
    section_numba.fused_trials((*reference, *padding), kernel.packed, expected)
    assert np.array_equal(kernel.trials(other, 57, 16), expected)
