"""The uncertainty sources of a calibration, each switchable, and their settings."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from robocal_uncertainty.core.simulation import EncoderNoise, TrackerNoise
from robocal_uncertainty.errors import ConfigError

__all__ = ["SOURCES", "SOURCE_DESCRIPTIONS", "UncertaintySettings", "parse_sources"]

SOURCE_DESCRIPTIONS: dict[str, str] = {
    "tracker": "laser-tracker noise on every measured point",
    "encoder": "encoder noise on every joint reading, and on the test configuration",
    "lambda": "regularisation parameter drawn over its valid range around the L-curve optimum",
    "n_poses": "number of poses used, drawn between a minimum and all (random subsets)",
    "pose_choice": "choice of poses: random subsets of fixed size",
    "residual": (
        "residual scatter left after calibration (model inadequacy): residual bootstrap "
        "on the data and a resampled residual added to each prediction"
    ),
}
SOURCES: tuple[str, ...] = tuple(SOURCE_DESCRIPTIONS)


def parse_sources(text: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Parse ``"tracker,encoder"`` or ``"all"`` into a tuple of known source names.

    Raises
    ------
    ConfigError
        Unknown or empty source names.
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    names = [s.strip() for s in items if s.strip()]
    if names == ["all"]:
        return SOURCES
    unknown = [s for s in names if s not in SOURCE_DESCRIPTIONS]
    if unknown:
        msg = f"unknown uncertainty source(s) {unknown}; known: {', '.join(SOURCES)} or 'all'"
        raise ConfigError(msg)
    if not names:
        msg = f"no uncertainty source given; known: {', '.join(SOURCES)}"
        raise ConfigError(msg)
    return tuple(dict.fromkeys(names))


@dataclass(frozen=True)
class UncertaintySettings:
    """What a calibration Monte Carlo perturbs and how.

    Parameters
    ----------
    sources : tuple of str
        Subset of :data:`SOURCES`.
    tracker_noise : TrackerNoise
        Uniform +-(a + b L) per coordinate [m]; L is the distance from the tracker
        (the tracker frame origin, or `tracker_xyz` when points are in the base frame).
    encoder_noise : EncoderNoise
        Uniform +-half_width per joint [rad].
    lambda_range : (float, float) or None
        Range of lambda for the ``lambda`` source, in the column-scaled units of the
        identification; None means [lambda*/5, 5 lambda*] around the chosen lambda*.
    min_poses : int or None
        Smallest pose count for the ``n_poses`` source; None means
        max(ceil(40/3), ceil(1.5 n_identifiable / 3)) as the seed's 40 equations.
    subset_size : int or None
        Pose count for the ``pose_choice`` source; None means round(33/53 n_poses),
        the seed's ratio.
    tracker_xyz : (float, float, float)
        Tracker position in the robot base frame [m], for MPE distances when the campaign
        is in the base frame.
    gauss_newton_iterations : int
        Maximum re-identification iterations per trial (warm-started at the calibration).
    jacobian : {"frozen", "exact"}
        ``frozen``: chord iterations with the calibration's Jacobian (fast, default);
        ``exact``: Gauss-Newton with each trial's own Jacobian (reference).
    """

    sources: tuple[str, ...] = ("tracker", "encoder")
    tracker_noise: TrackerNoise = field(default_factory=TrackerNoise)
    encoder_noise: EncoderNoise = field(default_factory=EncoderNoise)
    lambda_range: tuple[float, float] | None = None
    min_poses: int | None = None
    subset_size: int | None = None
    tracker_xyz: tuple[float, float, float] = (2.0, 0.5, 0.3)
    gauss_newton_iterations: int = 4
    jacobian: Literal["frozen", "exact"] = "frozen"

    def __post_init__(self) -> None:
        object.__setattr__(self, "sources", parse_sources(self.sources))
        if self.lambda_range is not None:
            lo, hi = (float(v) for v in self.lambda_range)
            if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0 or hi <= lo:
                msg = f"lambda_range must be 0 <= low < high, got {self.lambda_range}"
                raise ConfigError(msg)
        for name in ("min_poses", "subset_size"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                msg = f"{name} must be a positive integer, got {value!r}"
                raise ConfigError(msg)
        if self.jacobian not in ("frozen", "exact"):
            msg = f"jacobian must be 'frozen' or 'exact', got {self.jacobian!r}"
            raise ConfigError(msg)
        if self.gauss_newton_iterations < 1:
            msg = f"gauss_newton_iterations must be >= 1, got {self.gauss_newton_iterations}"
            raise ConfigError(msg)
