"""The validation service: prove an uncertainty statement on held-out measurements.

:func:`validate` chooses the held-out poses (a random split, k folds, or a second
campaign), then calibrates and evaluates the training poses exactly as
:func:`~robocal_uncertainty.app.evaluate` does and counts how often the held-out
measurements fall inside the stated intervals
(:func:`~robocal_uncertainty.uncertainty.holdout.validate_holdout`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.field_kriging import KrigingBasis
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, CalibrationUncertainty
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.field_kriging import corrected_uncertainty, field_basis
from robocal_uncertainty.uncertainty.holdout import (
    HoldoutValidation,
    StatementAdjustment,
    split_campaign,
    validate_holdout,
)

__all__ = ["DEFAULT_HOLDOUT_FRACTION", "FieldCorrectionCheck", "validate", "validate_with_field_correction"]

DEFAULT_HOLDOUT_FRACTION = 0.25
"""Fraction of the poses held out when no split is chosen."""


def validate(
    model: RobotModel,
    campaign: Campaign,
    options: EvaluationSettings,
    *,
    train_poses: int | None = None,
    holdout_fraction: float | None = None,
    k_folds: int | None = None,
    validation_campaign: Campaign | None = None,
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
    adjust_statement: StatementAdjustment | None = None,
) -> HoldoutValidation:
    """Hold out measurements, predict them from the rest, and count the coverage.

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
        Calibration campaign.
    options : EvaluationSettings
        Lambda, sources, a fixed trial count, seed and coverage of the statement under test
        (``test_joints`` is not used: the held-out joint readings are the test
        configurations); ``frame`` must be ``"measurement"``.
    train_poses, holdout_fraction, k_folds : optional
        At most one: calibrate on this many random poses; hold out this fraction at random
        (default :data:`DEFAULT_HOLDOUT_FRACTION`); or k-fold cross-validation.
    validation_campaign : Campaign, optional
        A second campaign of the same tracker set-up, held out whole (no split then).
    workers : int
        Local worker processes; never changes the result.
    progress : callable, optional
        ``progress(line)`` once per fold.
    adjust_statement : callable, optional
        What is checked in place of each fold's statement (see
        :func:`~robocal_uncertainty.uncertainty.holdout.validate_holdout`;
        :func:`validate_with_field_correction` uses it).

    Raises
    ------
    ConfigError
        Adaptive trials, the base frame, more than one split option, or a split option with
        a validation campaign.
    InputError
        A validation campaign measured in another set-up (its frame moved, see
        :func:`~robocal_uncertainty.uncertainty.holdout.validate_holdout`).
    """
    _check_options(options, (train_poses, holdout_fraction, k_folds), validation_campaign)
    chosen = [x is not None for x in (train_poses, holdout_fraction, k_folds)]
    splits = None
    if validation_campaign is None:
        fraction = holdout_fraction if any(chosen) else DEFAULT_HOLDOUT_FRACTION
        splits = split_campaign(
            campaign.n_poses,
            n_train=train_poses,
            holdout_fraction=fraction if train_poses is None and k_folds is None else None,
            k_folds=k_folds,
            seed=options.seed,
        )
    return validate_holdout(
        model,
        campaign,
        splits=splits,
        validation_campaign=validation_campaign,
        settings=options.uncertainty,
        lambda_=options.lambda_,
        trials=int(options.trials),
        coverage=options.coverage,
        seed=options.seed,
        workers=workers,
        progress=progress,
        backend=options.backend,
        adjust_statement=adjust_statement,
    )


def _check_options(
    options: EvaluationSettings, split_options: tuple[object, object, object], validation_campaign: Campaign | None
) -> None:
    """Refuse what :func:`validate` cannot validate (see its Raises)."""
    chosen = [x is not None for x in split_options]
    if options.trials == "auto":
        raise ConfigError("validate needs a fixed number of --trials, not auto")
    if options.frame != "measurement":
        # Held-out measurements exist only in the campaign's frame; moving them into the base
        # frame would use the uncertain identified base and bias the comparison.
        raise ConfigError(
            "validate compares with measurements, so it works in the measurement frame only (no --frame base)"
        )
    if sum(chosen) > 1:
        raise ConfigError("give only one of --train-poses, --holdout-fraction, --k-folds")
    if validation_campaign is not None and any(chosen):
        # The second campaign is held out whole and the first used whole for training: a split
        # option would be ignored without a word.
        given = next(o for o, c in zip(("--train-poses", "--holdout-fraction", "--k-folds"), chosen) if c)
        msg = (
            f"{given} splits the campaign, --validation-campaign holds out a second campaign whole and "
            "trains on the first whole: give one or the other"
        )
        raise ConfigError(msg)


@dataclass(frozen=True, eq=False)
class FieldCorrectionCheck:
    """The held-out accuracy with and without the model-error field's correction.

    Attributes
    ----------
    uncorrected_rms, corrected_rms : ndarray, shape (3,) [m]
        Per axis (x, y, z of the validation's frame): RMS of measured minus predicted without
        the correction (the calibrated Monte Carlo mean) and with it.
    uncorrected_rms_3d, corrected_rms_3d : float [m]
        The same over the three axes (sqrt of the mean squared 3-D error).
    median_statement_ratio : float
        Median over the held-out poses of the corrected statement's position standard
        uncertainty over the uncorrected one's (root of the covariance traces; near 1: the
        correction knows little there).
    """

    uncorrected_rms: NDArray[np.float64]
    corrected_rms: NDArray[np.float64]
    uncorrected_rms_3d: float
    corrected_rms_3d: float
    median_statement_ratio: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (m)."""
        return {
            "uncorrected_rms_m": [float(v) for v in self.uncorrected_rms],
            "corrected_rms_m": [float(v) for v in self.corrected_rms],
            "uncorrected_rms_3d_m": self.uncorrected_rms_3d,
            "corrected_rms_3d_m": self.corrected_rms_3d,
            "median_statement_ratio": self.median_statement_ratio,
        }


@dataclass
class _FieldCorrector:
    """Corrects each fold's statement and records what it moved (in the order the folds pool)."""

    settings: EvaluationSettings
    bases: dict[int, KrigingBasis] = dataclasses.field(default_factory=dict)
    shifts: list[NDArray[np.float64]] = dataclasses.field(default_factory=list)
    ratios: list[NDArray[np.float64]] = dataclasses.field(default_factory=list)

    def __call__(
        self, result: CalibrationUncertainty, calibration: IdentificationResult, train: Campaign
    ) -> CalibrationUncertainty:
        key = id(calibration)  # one basis per fold (its chunks share the calibration)
        if key not in self.bases:
            self.bases = {key: field_basis(calibration, train, self.settings.uncertainty)}
        corrected = corrected_uncertainty(result, self.bases[key])
        before = np.stack([pose.mean for pose in result.poses])
        after = np.stack([pose.mean for pose in corrected.poses])
        self.shifts.append(after - before)
        stated = np.stack([np.diagonal(pose.covariance) for pose in result.poses]).sum(axis=1)
        kept = np.stack([np.diagonal(pose.covariance) for pose in corrected.poses]).sum(axis=1)
        self.ratios.append(np.sqrt(kept / stated))
        return corrected


def validate_with_field_correction(
    model: RobotModel,
    campaign: Campaign,
    options: EvaluationSettings,
    **split: Any,
) -> tuple[HoldoutValidation, FieldCorrectionCheck]:
    """:func:`validate` of the statement with the model-error field's correction, and the gain.

    Each fold's training calibration gives its field (with the kriging variance's
    cross-validated factors, as its calibration file would hold them) and each held-out pose's
    statement is corrected as ``evaluate --field-correction`` corrects it
    (:func:`~robocal_uncertainty.uncertainty.field_kriging.corrected_uncertainty`): the coverage
    counted is that of the corrected statement, and the held-out RMS is given with and without the
    correction (the same Monte Carlo, moved by the kriged mean).

    Parameters
    ----------
    model, campaign, options
        As for :func:`validate`.
    **split
        The split options of :func:`validate` (``train_poses``, ``holdout_fraction``,
        ``k_folds``, ``validation_campaign``, ``workers``, ``progress``).

    Raises
    ------
    ConfigError
        As :func:`validate`, and a fold whose training calibration estimates no field (the
        model explains its points, or no ``residual`` source): nothing to correct.
    """
    corrector = _FieldCorrector(options)
    validation = validate(model, campaign, options, adjust_statement=corrector, **split)
    shifts = np.concatenate(corrector.shifts)[:, :N_AXES]
    errors = validation.errors[:, :N_AXES]
    uncorrected = errors + shifts
    check = FieldCorrectionCheck(
        uncorrected_rms=np.sqrt(np.mean(uncorrected**2, axis=0)),
        corrected_rms=np.sqrt(np.mean(errors**2, axis=0)),
        uncorrected_rms_3d=float(np.sqrt(np.mean(np.sum(uncorrected**2, axis=1)))),
        corrected_rms_3d=float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))),
        median_statement_ratio=float(np.median(np.concatenate(corrector.ratios))),
    )
    return validation, check
