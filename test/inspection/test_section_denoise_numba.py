"""The denoising's compiled local fits (numba backend) against the numpy reference path."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.core.instruments.cmm import CmmInstrument, point_displacements
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.inspection.coverage_study import Feature, feature_deviation
from robocal_uncertainty.inspection.denoise import (
    _compiled_local_choice,
    _hat_matrix,
    _local_choice,
    denoise_section,
    normal_noise_variance,
    smooth_normal_deviation,
)
from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.section import evaluate_section
from robocal_uncertainty.inspection.section_mc import section_sources
from robocal_uncertainty.inspection.simulate import simulate_section_scan

pytest.importorskip("numba")

RELATIVE = 1e-12


def _close(a: np.ndarray, b: np.ndarray) -> None:
    """Equal to RELATIVE of the larger magnitude (sums taken in another order)."""
    scale = max(float(np.abs(a).max()), 1e-300)
    assert np.abs(a - b).max() <= RELATIVE * scale, np.abs(a - b).max() / scale


@pytest.fixture(scope="module")
def scan(rotor37_curve: NominalCurve) -> tuple:
    """A noisy 1 836-point scan with a narrow bump (the local windows narrow there) and its sources."""
    features = (Feature("bump", 0.4214, 4e-6, 6e-3), Feature("dent", 0.2, 5e-6, 4e-3))
    cloud = simulate_section_scan(
        rotor37_curve,
        1836,
        form_amplitude=5e-6,
        deviation=lambda u: feature_deviation(u, features, rotor37_curve.period),
    )
    clean = evaluate_section(cloud, rotor37_curve)
    sources = section_sources(clean, CmmInstrument(), probe_vectors=cloud.probe_vectors)
    noisy = clean.points + point_displacements(sources, np.random.default_rng(3))[0]
    return evaluate_section(noisy, rotor37_curve), sources


def test_compiled_fit_and_leverage_equal_numpy(scan: tuple, rotor37_curve: NominalCurve) -> None:
    evaluation, _ = scan
    reg = evaluation.registration
    period = rotor37_curve.period
    at = np.arange(0, reg.residual.shape[0], 7)
    # Narrow and wide windows; the wide ones wrap past the contour's start at the first points.
    for half_width in (4e-3, 20e-3, 120e-3):
        for where in (None, at):
            numpy_fit, numpy_lev = smooth_normal_deviation(
                reg.parameter, reg.residual, reg.normal, period, half_width, at=where
            )
            fit, lev = smooth_normal_deviation(
                reg.parameter, reg.residual, reg.normal, period, half_width, at=where, backend="numba"
            )
            _close(numpy_fit, fit)
            _close(numpy_lev, lev)


def test_compiled_local_choice_and_hat_matrix_equal_numpy(scan: tuple, rotor37_curve: NominalCurve) -> None:
    evaluation, sources = scan
    reg = evaluation.registration
    variance = normal_noise_variance(sources, reg.normal)
    tried = (4e-3, 6e-3, 9e-3, 14e-3, 20e-3, 30e-3)
    args = (reg.parameter, reg.residual, reg.normal, variance, rotor37_curve.period, tried)
    fit, smooth, sd, chosen, rows = _local_choice(*args)
    c_fit, c_smooth, c_sd, c_chosen, c_hat = _compiled_local_choice(*args)
    # The windows chosen per point are the same (several of them: the features narrow them).
    np.testing.assert_array_equal(chosen, c_chosen)
    assert np.unique(chosen).size >= 3
    for a, b in ((fit, c_fit), (smooth, c_smooth), (sd, c_sd)):
        _close(a, b)
    hat = _hat_matrix(rows, chosen, reg.residual.shape[0]).toarray()
    _close(hat, c_hat.toarray())
    # Canonical CSR: every row's columns strictly ascending (a wrapped window lists columns 0, 1, ... first).
    inner = np.ones(c_hat.indices.size - 1, dtype=bool)
    inner[c_hat.indptr[1:-1] - 1] = False
    assert (np.diff(c_hat.indices)[inner] > 0).all()


def test_denoised_cloud_equal_numpy(scan: tuple, rotor37_curve: NominalCurve) -> None:
    evaluation, sources = scan
    reference = denoise_section(evaluation, sources, rotor37_curve.period)
    compiled = denoise_section(evaluation, sources, rotor37_curve.period, backend="numba")
    for name in ("points", "deviation", "smooth_deviation", "smooth_std"):
        _close(getattr(reference, name), getattr(compiled, name))
    np.testing.assert_array_equal(reference.local_half_width, compiled.local_half_width)
    assert reference.half_width == compiled.half_width
    _close(np.asarray(reference.risk), np.asarray(compiled.risk))
    assert reference.check.p_value == compiled.check.p_value
    assert abs(reference.check.statistic - compiled.check.statistic) <= RELATIVE * reference.check.statistic


def test_unknown_denoise_backend_is_refused(scan: tuple, rotor37_curve: NominalCurve) -> None:
    evaluation, sources = scan
    with pytest.raises(ConfigError, match="numpy or numba"):
        denoise_section(evaluation, sources, rotor37_curve.period, backend="cupy")
