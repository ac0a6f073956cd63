"""The model-error field's correction (kriging) applied to an uncertainty statement.

:mod:`~robocal_uncertainty.core.field_kriging` gives the field's conditional mean and kriging
covariance at some configurations; this module puts them into the statements the commands make,
one way for all of them (``fk``, ``map``, ``evaluate``, ``validate``, the uncertainty node): the
positions move by the conditional mean and the kriging covariance takes the place of the field's
prior in the statement's covariance (:func:`corrected_statement`); a Monte Carlo statement's trials
are mapped affinely onto that mean and covariance, so its intervals, regions and held-out checks
are computed as before, from trials (:func:`corrected_uncertainty`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.calibration_file import apply_calibration, calibration_to_dict
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.field_kriging import KrigedPoints, KrigingBasis, krige, kriging_basis
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.montecarlo.region import coverage_region
from robocal_uncertainty.montecarlo.summary import summarize
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, CalibrationUncertainty, GumPose
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = [
    "calibration_kriging_basis",
    "corrected_statement",
    "corrected_uncertainty",
    "correction_warning",
    "field_basis",
    "output_rotation",
]

Array = NDArray[np.float64]


def calibration_kriging_basis(
    calibration: IdentificationResult, campaign: Campaign, tracker_noise: TrackerNoise, encoder_noise: EncoderNoise
) -> KrigingBasis:
    """:func:`kriging_basis` of a calibration made in this process (what its ``calibrate --json`` file would hold).

    Raises
    ------
    ConfigError
        The calibration's residuals show no model-error field (the model explains them).
    """
    from robocal_uncertainty.uncertainty.sessions.state import session_state  # the sessions import this module's peers

    state, _ = session_state(calibration, campaign, tracker_noise, encoder_noise)
    data = calibration_to_dict(calibration, robot=calibration.model.name, session=state)
    model = apply_calibration(calibration.model, data, where="the calibration")
    return kriging_basis(data, model, where="the calibration")


def corrected_statement(kriged: KrigedPoints, covariance: Array, rotation: Array | None = None) -> tuple[Array, Array]:
    """A statement's shift and covariance once the field's correction is applied.

    The kriging covariance replaces the field's prior; what the statement's covariance carries
    beyond that prior (other sources, a different model-error scale) stays:
    ``Cov = R Cov_krig R^T + psd(Cov_stated - R Cov_prior R^T)`` (``psd``: negative eigenvalues set
    to 0, so the correction never removes more than the field's prior).

    Parameters
    ----------
    kriged : KrigedPoints
        At the statement's configurations (measurement frame).
    covariance : ndarray, shape (n, 3, 3) [m^2]
        The uncorrected statement's covariance per configuration, in the output frame.
    rotation : ndarray, shape (3, 3), optional
        Measurement frame to the output frame (default the identity).

    Returns
    -------
    (ndarray of shape (n, 3), ndarray of shape (n, 3, 3))
        The shift to add to the positions [m] and the corrected covariance [m^2].
    """
    rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    post = np.einsum("ij,njk,lk->nil", rot, kriged.covariance, rot)
    prior = np.einsum("ij,njk,lk->nil", rot, kriged.prior_covariance, rot)
    vals, vecs = np.linalg.eigh(np.asarray(covariance, dtype=np.float64) - prior)
    beyond = np.einsum("nij,nj,nkj->nik", vecs, np.clip(vals, 0.0, None), vecs)
    return np.asarray(kriged.mean @ rot.T, dtype=np.float64), np.asarray(post + beyond, dtype=np.float64)


def field_basis(calibration: IdentificationResult, campaign: Campaign, settings: UncertaintySettings) -> KrigingBasis:
    """:func:`calibration_kriging_basis` with the noise models of `settings` (the statement's)."""
    return calibration_kriging_basis(
        calibration,
        campaign.reorder_joints(calibration.model.joint_names),
        settings.tracker_noise,
        settings.encoder_noise,
    )


def output_rotation(calibration: IdentificationResult, frame: str) -> Array:
    """Measurement frame to the statement's output frame: the identity, or ``R_wb^T`` for the base frame."""
    p = calibration.estimate
    b0 = calibration.model.layout.base_index
    return np.eye(3) if frame != "base" else np.asarray(rpy_to_matrix(p[b0 + 3 : b0 + 6]).T, dtype=np.float64)


def correction_warning(kriged: KrigedPoints) -> str:
    """The line a corrected statement carries: what was added, and where it holds."""
    ratio = kriged.std_ratio
    size = np.linalg.norm(kriged.mean, axis=1) * 1e6
    return (
        "positions include the model-error field's conditional mean given the calibration residuals (kriging; "
        f"median {np.median(size):.1f} um, largest {np.max(size):.1f} um) and the statement its kriging covariance "
        f"(kriging std / uncorrected std: median {np.median(ratio):.2f}); it holds for the calibration's session "
        "only, and a URDF cannot carry it"
    )


def corrected_uncertainty(result: CalibrationUncertainty, basis: KrigingBasis) -> CalibrationUncertainty:
    """A Monte Carlo statement with the field's correction at its test configurations.

    Each configuration's position trials ``x`` are mapped to ``mean + d + L_c L^-1 (x - mean)``
    (``d`` the conditional mean in the output frame, ``L`` and ``L_c`` Cholesky factors of the
    trials' covariance and of the corrected one, :func:`corrected_statement`): the trials keep
    their shape (the field scale's heavy tails) and get the corrected mean and covariance, so the
    summaries, coverage intervals and regions are the Monte Carlo's, recomputed. The first-order
    GUM statement gets the same shift and covariance; its JCGM 101 section 8 flags are those of
    the uncorrected statement. Orientations and parameters are unchanged (the field is one of
    positions).

    Parameters
    ----------
    result : CalibrationUncertainty
        The uncorrected statement (output frame measurement or base).
    basis : KrigingBasis
        The calibration's field (:func:`calibration_kriging_basis`), of ``result.calibration``.

    Raises
    ------
    InputError
        A configuration whose trials have no spread (no covariance to map).
    """
    calibration = result.calibration
    n = len(result.poses)
    q = np.stack([pose.joint_positions for pose in result.poses])
    kriged = krige(basis, calibration.model.layout, calibration.estimate, q)
    rot = output_rotation(calibration, result.frame)
    stated = np.stack([pose.covariance for pose in result.poses])
    shift, covariance = corrected_statement(kriged, stated, rot)
    positions = result.samples[:, : N_AXES * n].reshape(-1, n, N_AXES)
    mean = positions.mean(axis=0)
    try:
        l_old = np.linalg.cholesky(stated)
        l_new = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError as err:
        msg = "a test configuration's trials have no spread in some direction: the field's correction cannot map them"
        raise InputError(msg) from err
    transform = l_new @ np.linalg.inv(l_old)
    moved = mean + shift + np.einsum("nij,mnj->mni", transform, positions - mean)
    samples = np.concatenate((moved.reshape(-1, N_AXES * n), result.samples[:, N_AXES * n :]), axis=1)
    summary = summarize(samples[:, : N_AXES * n], result.coverage_probability)
    gum_shift, gum_cov = corrected_statement(kriged, np.stack([pose.gum.covariance for pose in result.poses]), rot)
    poses = []
    for i, pose in enumerate(result.poses):
        cols = slice(N_AXES * i, N_AXES * (i + 1))
        axes = tuple(summary.outputs[cols])
        region = None if pose.region is None else coverage_region(moved[:, i], result.coverage_probability)
        poses.append(
            dataclasses.replace(
                pose,
                mean=np.array([a.estimate for a in axes]),
                covariance=summary.covariance[cols, cols],
                axes=axes,
                region=region,
                gum=_corrected_gum(pose.gum, gum_shift[i], gum_cov[i]),
            )
        )
    return dataclasses.replace(
        result,
        poses=tuple(poses),
        samples=samples,
        warnings=(*result.warnings, correction_warning(kriged)),
    )


def _corrected_gum(gum: GumPose, shift: Array, covariance: Array) -> GumPose:
    """`gum` moved by `shift` with `covariance` (unchanged where not applicable)."""
    if not gum.applicable or not np.isfinite(gum.covariance).all():
        return gum
    std = np.sqrt(np.clip(np.diagonal(covariance), 0.0, None))
    return dataclasses.replace(
        gum,
        estimate=np.asarray(gum.estimate) + shift,
        covariance=covariance,
        standard_uncertainty=std,
        expanded_uncertainty=gum.coverage_factor * std,
    )
