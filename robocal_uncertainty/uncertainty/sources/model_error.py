"""The model-error source: what the kinematic model cannot explain, at the poses and the predictions.

By default a model-error field (:mod:`~robocal_uncertainty.uncertainty.model_error_draws`): one
draw correlated over the calibration poses and the test configurations; with
``--independent-model-error`` (or where the field is not identified) a residual bootstrap
independent from pose to pose.
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
    "model error left after calibration (model inadequacy): a field over the joint configurations "
    "(restricted maximum likelihood on the residuals), drawn jointly on the data and the predictions; "
    "with --independent-model-error a residual bootstrap, independent from pose to pose",
    True,
    _residual,
    role="model_error",
    in_sweeps=True,
    to_settings=lambda values: {"model_error": "independent" if values["independent_model_error"] else "field"},
    options=(
        SourceOption(
            "--independent-model-error",
            "draw the model error independently from pose to pose (a residual bootstrap) instead of the "
            "default field over the joint configurations, drawn jointly over the calibration poses and the "
            "test configurations (for comparison; see README)",
            "model",
            flag_only=True,
            parameters=(
                NodeParameter(
                    "independent_model_error",
                    False,
                    "Draw the residual source's model error independently from pose to pose instead of as a "
                    "field over the joint configurations",
                    "",
                ),
            ),
        ),
    ),
)
