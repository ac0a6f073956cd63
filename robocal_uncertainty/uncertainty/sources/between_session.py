"""The between-session source: a future session's effects on every prediction.

The component itself (effects, covariance) is estimated from several sessions in
:mod:`robocal_uncertainty.uncertainty.sessions.between`; the settings carry it, so this
module needs only its covariance and names, never that module.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from robocal_uncertainty.montecarlo.distributions import CorrelatedNormal, IndependentRectangular
from robocal_uncertainty.uncertainty.sources.base import AdditiveSource, Source, SourceOption, SourceSpec, TrialContext

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sources.settings import UncertaintySettings

__all__ = ["BETWEEN_SESSION"]


def _between_session_source(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    """A future session's effects (joint offsets, length scale) added to every prediction.

    One draw per trial moves every test configuration together (the same session); zeros when
    the settings carry no between-session component or the measurement holds orientations.
    """
    d = ctx.measurement_dimension
    segments = (("predictions", (ctx.n_test, d)),)
    between = settings.between_session
    g = ctx.test_effect_jacobian
    if between is None or g is None or d != 3:
        return AdditiveSource("between_session", IndependentRectangular(np.zeros(ctx.n_test * d)), segments)
    flat = g.reshape(ctx.n_test * 3, -1)
    cov = flat @ between.covariance @ flat.T
    return AdditiveSource("between_session", CorrelatedNormal(np.zeros(ctx.n_test * 3), 0.5 * (cov + cov.T)), segments)


BETWEEN_SESSION = SourceSpec(
    "between_session",
    "between-session reproducibility: a future session's joint offsets and link length scale "
    "(estimated from several sessions; calibrate --sessions), one draw per trial for every prediction",
    True,
    _between_session_source,
    options=(
        SourceOption(
            "--between-session",
            "a calibration written by calibrate --sessions: add its between-session component (source "
            "between_session) so the statement holds for a future session",
            "session",
            type=str,
            metavar=("CAL.json",),
        ),
    ),
)
