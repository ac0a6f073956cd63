"""The model-error source: what the kinematic model cannot explain, at the poses and the predictions.

A residual bootstrap independent from pose to pose by default; with a model-error field
(:mod:`~robocal_uncertainty.uncertainty.model_error_draws`) one draw correlated over the
calibration poses and the test configurations.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from robocal_uncertainty.montecarlo.distributions import Empirical, IndependentCopies
from robocal_uncertainty.uncertainty.sources.base import (
    AdditiveSource,
    NodeParameter,
    Source,
    SourceOption,
    SourceSpec,
    TrialContext,
)

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sources.settings import UncertaintySettings

__all__ = ["RESIDUAL"]


def _residual(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    d = ctx.measurement_dimension
    segments = (("points", (ctx.n_poses, d)), ("predictions", (ctx.n_test, d)))
    if ctx.model_error_field is not None:
        # One field over the calibration poses and the test configurations: what the re-fit
        # absorbs of it at the poses is correlated with what is left at the test configurations.
        return AdditiveSource("residual", ctx.model_error_field, segments)
    return AdditiveSource(
        "residual", IndependentCopies(Empirical(ctx.model_errors), ctx.n_poses + ctx.n_test), segments
    )


RESIDUAL = SourceSpec(
    "residual",
    "model error left after calibration (model inadequacy): a Gaussian field over the joint "
    "configurations (restricted maximum likelihood on the residuals), drawn jointly on the data and "
    "the predictions with --model-error-field; else a residual bootstrap, independent from pose to pose",
    True,
    _residual,
    role="model_error",
    in_sweeps=True,
    to_settings=lambda values: {"model_error": "field" if values["model_error_field"] else "independent"},
    options=(
        SourceOption(
            "--model-error-field",
            "draw the model error as a Gaussian field over the joint configurations, jointly over the "
            "calibration poses and the test configurations, instead of the default residual bootstrap, "
            "independent from pose to pose (the field states 53-pose UR10 campaigns too narrow; see README)",
            "model",
            flag_only=True,
            parameters=(
                NodeParameter(
                    "model_error_field",
                    False,
                    "Draw the residual source's model error as a field over the joint configurations instead of "
                    "independently from pose to pose",
                    "",
                ),
            ),
        ),
    ),
)
