"""The kriging variance checked on the calibration's own held-out folds, and its record in the file.

The field's hyperparameters come from a restricted likelihood that the closest pairs of poses
dominate (a campaign that repeats poses), so the exponential kernel they give is right next to a
calibration pose and too confident a few tenths of a radian away
(``benchmarks/study_field_kriging.py``). :func:`cross_validated_factors` measures that on the
calibration's own poses and gives per-axis factors (>= 1) on the kriging variance. They cost a
few seconds to a minute (five refits and krigings of the campaign), so they are computed once,
when the calibration file is written (:func:`factors_record`, ``model_error.field.cross_validation``,
with what they were computed from), and read back by every correction (:func:`stored_factors`).
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.field_kriging import KrigingBasis, krige, parameter_columns
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.robot_model import ParameterLayout
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "CROSS_VALIDATION_BINS",
    "CROSS_VALIDATION_FOLDS",
    "CROSS_VALIDATION_SEED",
    "CrossValidation",
    "basis_fingerprint",
    "cross_validated_factors",
    "factors_record",
    "stored_factors",
]

Array = NDArray[np.float64]

CROSS_VALIDATION_FOLDS = 5
"""Folds of :func:`cross_validated_factors`."""
CROSS_VALIDATION_BINS = 3
"""Std-ratio bins of :func:`cross_validated_factors` (equal numbers of poses)."""
CROSS_VALIDATION_SEED = 0
"""Seed of the folds' assignment (with the number of poses)."""


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """The correction on the calibration's own held-out folds.

    Attributes
    ----------
    ratios : ndarray, shape (b,)
        Median std ratio of each bin.
    factors : ndarray, shape (b, 3)
        Per-axis variance factors (>= 1) that make each bin's mean squared standardised error 1.
    standardised : ndarray, shape (n_t, 3)
        Each pose's corrected error over its stated standard uncertainty (kriging and noise),
        per axis, before the factors.
    ratio : ndarray, shape (n_t,)
        Each pose's std ratio.
    """

    ratios: Array
    factors: Array
    standardised: Array
    ratio: Array


def _bin_factor(err2: Array, post: Array, noise: Array) -> float:
    """The factor f >= 1 with mean(err2 / (f post + noise)) = 1 (1 when already 1 or less at f = 1)."""
    f = 1.0
    for _ in range(50):
        value = float(np.mean(err2 / (f * post + noise)))
        if value <= 1.0 + 1e-6:
            break
        f *= value
    return f


def cross_validated_factors(
    basis: KrigingBasis,
    layout: ParameterLayout,
    parameters: Array,
    *,
    folds: int = CROSS_VALIDATION_FOLDS,
    bins: int = CROSS_VALIDATION_BINS,
    seed: int = CROSS_VALIDATION_SEED,
) -> CrossValidation:
    """Per-axis widening of the kriging variance from the calibration's own held-out folds.

    The poses are split into `folds` seeded folds; for each, the parameters are refitted
    (linearised, least squares) on the other poses and the field corrects the fold's residuals
    from theirs (:func:`krige`, the computation a new configuration gets). On real series the
    field's covariance (an exponential kernel whose hyperparameters repeated poses dominate) is
    right next to a calibration pose and too confident a few tenths of a radian away, and its
    per-pose shape is not right on every axis: the folds' squared standardised errors, binned
    by the std ratio (how much the correction knows there), give per-axis factors on the
    kriging variance. Never below 1: the folds only widen the field's own statement.
    """
    q_t = np.asarray(basis.joint_positions, dtype=np.float64)
    n_t = q_t.shape[0]
    r = np.asarray(basis.residuals, dtype=np.float64)
    noise = np.asarray(basis.noise, dtype=np.float64)
    cols = parameter_columns(layout, basis.gain_names)
    _, jac_t = forward_points_and_jacobian(layout, parameters, q_t)
    jac = jac_t[:, :, cols]
    n_folds = max(int(folds), 2)
    fold_of = np.random.default_rng(np.random.SeedSequence([int(seed), n_t])).permutation(n_t) % n_folds
    err2, post, ratio = np.empty((n_t, 3)), np.empty((n_t, 3)), np.empty(n_t)
    plain = dataclasses.replace(basis, factor_ratios=np.zeros(0), factor_axes=np.zeros((0, 3)))
    for f in range(n_folds):
        out, rest = np.flatnonzero(fold_of == f), np.flatnonzero(fold_of != f)
        a_rest = jac[rest].reshape(3 * rest.size, len(cols))
        gain_rest = np.asarray(np.linalg.pinv(a_rest, rcond=1e-10), dtype=np.float64)
        delta = gain_rest @ r[rest].reshape(-1)
        sub = dataclasses.replace(
            plain,
            joint_positions=q_t[rest],
            residuals=r[rest] - (a_rest @ delta).reshape(-1, 3),
            noise=noise[rest],
            gain=gain_rest,
        )
        kriged = krige(sub, layout, parameters, q_t[out])
        err2[out] = (r[out] - np.einsum("nik,k->ni", jac[out], delta) - kriged.mean) ** 2
        post[out] = np.diagonal(kriged.covariance, axis1=1, axis2=2)
        ratio[out] = kriged.std_ratio
    noise_diag = np.diagonal(noise, axis1=1, axis2=2)
    order = np.argsort(ratio)
    groups = np.array_split(order, max(1, min(int(bins), n_t // 30)))
    ratios = np.array([np.median(ratio[g]) for g in groups])
    factors = np.array([[_bin_factor(err2[g, a], post[g, a], noise_diag[g, a]) for a in range(3)] for g in groups])
    return CrossValidation(
        ratios=ratios, factors=factors, standardised=np.sqrt(err2 / (post + noise_diag)), ratio=ratio
    )


def basis_fingerprint(basis: KrigingBasis) -> str:
    """SHA-256 of what the folds' factors depend on: the poses, residuals, noise, field and gain.

    Lets a file's stored factors be checked against the file's field (a hand-edited or merged
    file would otherwise widen by factors of other poses)."""
    digest = hashlib.sha256()
    for array in (basis.joint_positions, basis.residuals, basis.noise, basis.per_pose_covariance, basis.gain):
        digest.update(np.ascontiguousarray(np.asarray(array, dtype="<f8")).tobytes())
    digest.update(np.array([basis.correlated_fraction, basis.length_scale], dtype="<f8").tobytes())
    digest.update(",".join(basis.gain_names).encode())
    return digest.hexdigest()


def factors_record(basis: KrigingBasis, layout: ParameterLayout, parameters: Array) -> dict[str, Any]:
    """``model_error.field.cross_validation`` of a calibration file: the factors and their provenance.

    Parameters
    ----------
    basis : KrigingBasis
        The file's field without factors (``kriging_basis(..., cross_validate=False)``).
    layout, parameters
        The calibrated model.
    """
    cross = cross_validated_factors(basis, layout, parameters)
    return {
        "ratios": [float(v) for v in cross.ratios],
        "factors_xyz": [[float(v) for v in row] for row in cross.factors],
        "folds": CROSS_VALIDATION_FOLDS,
        "bins": CROSS_VALIDATION_BINS,
        "seed": CROSS_VALIDATION_SEED,
        "n_poses": int(np.asarray(basis.joint_positions).shape[0]),
        "computed_from_sha256": basis_fingerprint(basis),
        "note": "per-axis factors (measurement frame) on the kriging variance, interpolated in the std ratio",
    }


def stored_factors(field_data: object, basis: KrigingBasis, *, where: str) -> tuple[Array, Array] | None:
    """The (ratios, factors) a calibration file stores for `basis`; None when it stores none.

    Raises
    ------
    ConfigError
        A malformed record, or one computed from other poses, residuals or field than the
        file's (one line).
    """
    record = field_data.get("cross_validation") if isinstance(field_data, dict) else None
    if record is None:
        return None
    try:
        ratios = np.asarray(record["ratios"], dtype=np.float64)
        factors = np.asarray(record["factors_xyz"], dtype=np.float64)
        source = str(record["computed_from_sha256"])
    except (TypeError, ValueError, KeyError) as err:
        msg = f"{where}: model_error.field.cross_validation is incomplete or not numeric ({err.__class__.__name__})"
        raise ConfigError(msg) from err
    if (
        ratios.ndim != 1
        or factors.shape != (ratios.size, 3)
        or not (np.isfinite(factors).all() and (factors >= 1).all())
    ):
        msg = f"{where}: model_error.field.cross_validation must hold b ratios and b x 3 factors >= 1"
        raise ConfigError(msg)
    if source != basis_fingerprint(basis):
        msg = (
            f"{where}: model_error.field.cross_validation was computed from other poses, residuals or field than "
            "the file holds (an edited file?): recalibrate ('calibrate --json') to get factors of this field"
        )
        raise ConfigError(msg)
    return ratios, factors
