"""The calibration session's error level on its own held-out poses, re-registered as a check.

A later check is tested against this level (:func:`~.level.level_test`): same-session checks
then agree with it by construction of the split, whatever scale the statement's model error has.
"""

from __future__ import annotations

import numpy as np

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.session import SessionState, ValidatedLevel
from robocal_uncertainty.uncertainty.sessions.level import check_level
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sessions.verification import fold_level
from robocal_uncertainty.uncertainty.sources.registry import default_sources

__all__ = ["LEVEL_FOLDS", "LEVEL_REPEATS", "validated_level"]


LEVEL_FOLDS = 5
"""Folds of the calibration campaign that validate its error level (:func:`validated_level`)."""
LEVEL_REPEATS = 4
"""Random splits into :data:`LEVEL_FOLDS` folds the validated level pools: one split's level
depends on which poses shared a fold; on the UR10 series B and D three to six splits steady it
(log scatter against the calibration's level on all its other poses 0.21-0.27 with one split,
0.16-0.18 with three) and give the fold-level dispersion 15-30 folds to be measured on."""


def validated_level(
    model: RobotModel,
    campaign: Campaign,
    tracker_noise: TrackerNoise,
    encoder_noise: EncoderNoise,
    *,
    lambda_: str | float = "auto",
    retool: bool = True,
    folds: int = LEVEL_FOLDS,
    seed: int = 0,
    repeats: int = LEVEL_REPEATS,
    sources: tuple[str, ...] = default_sources(),
    correlated: bool = True,
    reference: SessionState | None = None,
) -> ValidatedLevel:
    """The calibration session's error level on its own held-out poses, re-registered as a check.

    The campaign's poses are split at random (``seed``; `repeats` independent splits) into
    `folds` folds; each is predicted
    by a calibration of the others with the statement of `reference` (the full calibration's
    model error, so every fold is measured against the same statement; :func:`session_state`), re-registered
    (tracker pose, and the tool point with `retool`) as ``verify`` re-registers a check, and its
    observed squared error is set against the stated one
    (:func:`~.level.check_level`). A later check is tested against
    this level: same-session checks then agree with it by construction of the split, whatever
    scale the statement's model error has (a field whose scale the data hardly fix).

    Raises
    ------
    IdentifiabilityError
        Folds too small to re-register (fewer than about 4 poses each) or to calibrate without.
    """
    n = campaign.n_poses
    rng = np.random.default_rng(seed)
    checks = []
    for _ in range(repeats):
        order = rng.permutation(n)
        for part in np.array_split(order, folds):
            train = campaign.subset(np.sort(np.setdiff1d(order, part)))
            cal = identify(model, train, lambda_=lambda_, accept_unconverged=True)
            state, _ = session_state(
                cal,
                train,
                tracker_noise,
                encoder_noise,
                sources=sources,
                correlated=correlated,
                model_error_from=reference,
            )
            check = campaign.subset(np.sort(part))
            checks.append(fold_level(cal.model, state, check, retool=retool))
    return check_level(checks, seed=seed, repeats=repeats)
