"""The validation service: prove an uncertainty statement on held-out measurements.

:func:`validate` chooses the held-out poses (a random split, k folds, or a second
campaign), then calibrates and evaluates the training poses exactly as
:func:`~robocal_uncertainty.app.evaluate` does and counts how often the held-out
measurements fall inside the stated intervals
(:func:`~robocal_uncertainty.uncertainty.holdout.validate_holdout`).
"""

from __future__ import annotations

from collections.abc import Callable

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.holdout import HoldoutValidation, split_campaign, validate_holdout

__all__ = ["DEFAULT_HOLDOUT_FRACTION", "validate"]

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
