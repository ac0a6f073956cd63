"""What a calibration Monte Carlo perturbs and how: the enabled sources and their models."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sources.registry import default_sources, parse_sources

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sessions.between import BetweenSessions

__all__ = ["UncertaintySettings"]


def _is_numeric(value: object) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


@dataclass(frozen=True)
class UncertaintySettings:
    """What a calibration Monte Carlo perturbs and how.

    Parameters
    ----------
    sources : tuple of str
        Subset of :data:`SOURCES`; default :func:`default_sources` of a point campaign.
    tracker_noise : TrackerNoise
        Uniform +-(a + b L) per coordinate [m]; L is the distance from the tracker
        (the tracker frame origin, or `tracker_xyz` when points are in the base frame).
    encoder_noise : EncoderNoise
        Uniform +-half_width per revolute joint [rad], +-linear_half_width per prismatic one [m].
    lambda_range : (float, float) or None
        Range of lambda for the ``lambda`` source, in the column-scaled units of the
        identification; None means [lambda*/5, 5 lambda*] around the chosen lambda*.
    min_poses : int or None
        Smallest pose count for the ``n_poses`` source; None means
        max(ceil(40/3), ceil(1.5 n_identifiable / 3)) as the reference paper's 40 equations.
    subset_size : int or None
        Pose count for the ``pose_choice`` source; None means round(33/53 n_poses),
        the reference paper's ratio.
    tracker_xyz : (float, float, float)
        Tracker position in the robot base frame [m], for MPE distances when the campaign
        is in the base frame.
    gauss_newton_iterations : int
        Maximum re-identification iterations per trial (warm-started at the calibration).
    between_session : BetweenSessions or None
        Between-session component for the ``between_session`` source
        (:mod:`robocal_uncertainty.uncertainty.sessions.between`).
    jacobian : {"frozen", "exact"}
        ``frozen``: chord iterations with the calibration's Jacobian (fast, default);
        ``exact``: Gauss-Newton with each trial's own Jacobian (reference).
    model_error : {"field", "independent"}
        How the ``residual`` source draws the model error: ``field`` (default), a field
        correlated over the joint configurations, drawn jointly over the calibration poses and
        the test configurations (:mod:`~robocal_uncertainty.uncertainty.model_error_draws`; its
        held-out evidence on two UR10 series: ``benchmarks/study_model_error_field.py``);
        ``independent``, a residual bootstrap independent from pose to pose (the field's
        ``c = 0`` case, kept for comparison).
    """

    sources: tuple[str, ...] = field(default_factory=default_sources)
    tracker_noise: TrackerNoise = field(default_factory=TrackerNoise)
    encoder_noise: EncoderNoise = field(default_factory=EncoderNoise)
    lambda_range: tuple[float, float] | None = None
    min_poses: int | None = None
    subset_size: int | None = None
    tracker_xyz: tuple[float, float, float] = (2.0, 0.5, 0.3)
    gauss_newton_iterations: int = 4
    jacobian: Literal["frozen", "exact"] = "frozen"
    between_session: BetweenSessions | None = None
    model_error: Literal["field", "independent"] = "field"

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
        if self.model_error not in ("field", "independent"):
            msg = f"model_error must be 'field' or 'independent', got {self.model_error!r}"
            raise ConfigError(msg)
        if self.jacobian not in ("frozen", "exact"):
            msg = f"jacobian must be 'frozen' or 'exact', got {self.jacobian!r}"
            raise ConfigError(msg)
        iterations = self.gauss_newton_iterations
        if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
            msg = f"gauss_newton_iterations must be an integer >= 1, got {iterations!r}"
            raise ConfigError(msg)
        xyz = np.asarray(self.tracker_xyz, dtype=np.float64) if _is_numeric(self.tracker_xyz) else None
        if xyz is None or xyz.shape != (3,) or not np.isfinite(xyz).all():
            msg = f"tracker_xyz must be 3 finite coordinates [m], got {self.tracker_xyz!r}"
            raise ConfigError(msg)
