"""Instrument sources: laser-tracker position and orientation noise, encoder noise.

Smooth and additive. The tracker and encoder sources take their distribution from the
instrument (:mod:`robocal_uncertainty.core.instruments`): the GUM variance and the Monte Carlo
samples come from the definition the simulation draws from too.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.montecarlo.distributions import IndependentNormal, IndependentRectangular
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

__all__ = ["ENCODER", "TRACKER", "TRACKER_ORIENTATION"]


def _tracker(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    d = ctx.measurement_dimension
    # Position components only: the orientation noise is the tracker_orientation source.
    noise = settings.tracker_noise.distribution(
        ctx.distances, dimension=d, rotation_components=tuple(ctx.rotation_components)
    )
    return AdditiveSource("tracker", noise, (("points", (ctx.n_poses, d)),))


def _tracker_orientation(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    d = ctx.measurement_dimension
    segments = (("points", (ctx.n_poses, d)),)
    if ctx.rotation_std is None:
        # Points carry no orientation: a source of zeros keeps "all" valid for every campaign.
        return AdditiveSource("tracker_orientation", IndependentRectangular(np.zeros(ctx.n_poses * d)), segments)
    std = np.zeros((ctx.n_poses, d))
    std[:, list(ctx.rotation_components)] = np.asarray(ctx.rotation_std, dtype=np.float64)
    return AdditiveSource("tracker_orientation", IndependentNormal(std.reshape(-1)), segments)


def _encoder(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    segments = (("joints", (ctx.n_poses, ctx.n_joints)), ("test_joints", (ctx.n_test, ctx.n_joints)))
    prismatic = ctx.prismatic or (False,) * ctx.n_joints  # empty: all revolute
    noise = settings.encoder_noise.distribution(prismatic, ctx.n_poses + ctx.n_test)
    return AdditiveSource("encoder", noise, segments)


TRACKER_OPTIONS = (
    SourceOption(
        "--tracker-noise-um",
        "tracker error half-width a per coordinate, um (default %(default)s, uniform)",
        "noise",
        "um",
        float,
        5.0,
        parameters=(
            NodeParameter(
                "tracker_noise_um", 5.0, "Tracker error half-width a per coordinate (uniform)", "um", 0.0, 1e6
            ),
        ),
    ),
    SourceOption(
        "--tracker-noise-um-per-m",
        "distance-proportional part b of the MPE a + b L, um/m (default %(default)s)",
        "noise",
        "um/m",
        float,
        0.0,
        parameters=(
            NodeParameter(
                "tracker_noise_um_per_m",
                0.0,
                "Distance-proportional part b of the tracker MPE a + b L",
                "um/m",
                0.0,
                1e6,
            ),
        ),
    ),
)
"""Tracker MPE a + b L (settings: ``tracker_noise``)."""

ENCODER_OPTIONS = (
    SourceOption(
        "--encoder-noise-deg",
        "encoder error half-width, deg (default %(default)s, uniform); revolute joints",
        "noise",
        "deg",
        float,
        0.005,
        parameters=(NodeParameter("encoder_noise_deg", 0.005, "Encoder error half-width (uniform)", "deg", 0.0, 10.0),),
    ),
    SourceOption(
        "--linear-encoder-noise-um",
        "reading error half-width of a prismatic joint, um (default %(default)s, uniform)",
        "noise",
        "um",
        float,
        5.0,
        parameters=(
            NodeParameter(
                "linear_encoder_noise_um",
                5.0,
                "Reading error half-width of a prismatic joint (uniform)",
                "um",
                0.0,
                1e6,
            ),
        ),
    ),
)
"""Encoder reading half-widths, revolute and prismatic (settings: ``encoder_noise``)."""


def _tracker_settings(values: Mapping[str, Any]) -> Mapping[str, object]:
    return {
        "tracker_noise": TrackerNoise(a=values["tracker_noise_um"] * 1e-6, b=values["tracker_noise_um_per_m"] * 1e-6)
    }


def _encoder_settings(values: Mapping[str, Any]) -> Mapping[str, object]:
    half_width = float(np.radians(values["encoder_noise_deg"]))
    return {
        "encoder_noise": EncoderNoise(half_width=half_width, linear_half_width=values["linear_encoder_noise_um"] * 1e-6)
    }


TRACKER = SourceSpec(
    "tracker",
    "laser-tracker noise on every measured point",
    True,
    _tracker,
    role="point_noise",
    in_sweeps=True,
    options=TRACKER_OPTIONS,
    to_settings=_tracker_settings,
)
ENCODER = SourceSpec(
    "encoder",
    "encoder noise on every joint reading, and on the test configuration",
    True,
    _encoder,
    role="reading_noise",
    in_sweeps=True,
    options=ENCODER_OPTIONS,
    to_settings=_encoder_settings,
)
TRACKER_ORIENTATION = SourceSpec(
    "tracker_orientation",
    "laser-tracker orientation noise on every measured orientation (6-DOF campaigns; normal, "
    "the measurement's per-axis rotation std; zero for points)",
    True,
    _tracker_orientation,
)
