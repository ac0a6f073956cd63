"""What determines the result of one calibration uncertainty evaluation besides its data.

One frozen type, :class:`EvaluationSettings`, is what the command line parses, the nodes
read from their parameters, the application service and the Monte Carlo take, and the
tests construct; :func:`build_evaluation_settings` builds it from the values a user gives
(in the units of the options and parameters, µm and degrees), so the command line and the
uncertainty node cannot build it two ways. How the trials are run (workers, an executor,
progress) never changes the result and travels apart, in a
:class:`~robocal_uncertainty.montecarlo.executor.RunContext`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sources import UncertaintySettings, parse_sources, source_settings_fields

__all__ = ["EvaluationSettings", "build_evaluation_settings", "build_source_settings", "build_uncertainty_settings"]

Array = NDArray[np.float64]


def _positive_int(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        msg = f"{name} must be a positive integer, got {value!r}"
        raise ConfigError(msg)


@dataclass(frozen=True)
class EvaluationSettings:
    """Everything that determines a calibration and its uncertainty result besides the data.

    The data are the model, the campaign and (optionally) an existing calibration.

    Attributes
    ----------
    uncertainty : UncertaintySettings
        Sources and their models; default tracker and encoder noise at the reference paper's levels.
    lambda_ : {"auto", "gcv"} or float
        Lambda method of the calibration (when it is computed here; see
        :func:`~robocal_uncertainty.core.identification.identify`).
    test_joints : ndarray, shape (n_test, n_joints) [rad], optional
        Configurations at which the tool pose uncertainty is evaluated; required by
        :func:`robocal_uncertainty.app.evaluate` (the Monte Carlo call
        :func:`~robocal_uncertainty.uncertainty.calibration.evaluation.evaluate_uncertainty`
        takes its configurations as an argument).
    trials : int or "auto"
        Fixed number of trials, or the JCGM 101 §7.9 adaptive procedure.
    coverage : float
        Coverage probability p in (0, 1).
    seed : int
        Root seed; the result is reproducible from it (also of every budget run and sweep point).
    n_dig : int
        Significant digits of the adaptive procedure and the GUM validation.
    max_trials : int
        Cap of the adaptive procedure.
    block_size : int
        Trials per independent random stream (part of the result's identity).
    frame : {"measurement", "base"}
        Frame of the output positions. ``measurement``: the frame of the campaign's points, so
        results compare directly with measurements; for a tracker-frame campaign the
        uncertainty of the identified base enters. ``base``: the robot base frame (the
        identified base does not enter).
    orientation : bool
        Also evaluate the tool orientation (3 more columns per test configuration, see
        :mod:`~robocal_uncertainty.uncertainty.calibration.trials`); positions and parameters
        are the same either way, bit for bit. The adaptive procedure monitors the positions only.
    backend : {"numpy", "numba", "cupy", "auto"}
        Which trial kernels walk the chain (:mod:`robocal_uncertainty.kernels`): the same
        draws, the same result to rounding (1e-12 relative, tested), recorded in the result.
    accept_unconverged : bool
        Use an identification that did not converge instead of raising
        :class:`~robocal_uncertainty.errors.ConvergenceError`.
    budget : bool
        Also run each source alone (the uncertainty budget; only with two or more sources).
    budget_trials : int
        Trials of each budget run.
    sweeps : bool
        Also compute the uncertainty against lambda and against the number of equations.
    sweep_trials : int
        Trials per sweep point.

    Raises
    ------
    ConfigError
        Test joints not finite or not 2-D; a trial count that is not a positive integer.
    """

    uncertainty: UncertaintySettings = field(default_factory=UncertaintySettings)
    lambda_: str | float = "auto"
    test_joints: Array | None = None
    trials: int | str = 10_000
    coverage: float = 0.95
    seed: int = 0
    n_dig: int = 2
    max_trials: int = 2_000_000
    block_size: int = 10_000
    frame: str = "measurement"
    orientation: bool = True
    backend: str = "numpy"
    accept_unconverged: bool = False
    budget: bool = False
    budget_trials: int = 2_000
    sweeps: bool = False
    sweep_trials: int = 300

    def __post_init__(self) -> None:
        if self.test_joints is not None:
            q = np.array(self.test_joints, dtype=np.float64)
            if q.ndim == 1:
                q = q[None, :]
            if q.ndim != 2 or not np.isfinite(q).all():
                msg = f"test_joints must be finite, shape (n_test, n_joints), got shape {q.shape}"
                raise ConfigError(msg)
            q.setflags(write=False)
            object.__setattr__(self, "test_joints", q)
        if self.trials != "auto":
            trials = self.trials
            if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials <= 0:
                msg = f"trials must be a positive integer or 'auto', got {trials!r}"
                raise ConfigError(msg)
        for name in ("max_trials", "budget_trials", "sweep_trials"):
            _positive_int(name, getattr(self, name))

    def replace(self, **fields: Any) -> EvaluationSettings:
        """A copy with `fields` replaced (:func:`dataclasses.replace`, checked again).

        Raises
        ------
        TypeError
            An unknown field name.
        """
        unknown = sorted(set(fields) - _FIELDS)
        if unknown:
            msg = f"EvaluationSettings has no field {unknown[0]!r}"
            raise TypeError(msg)
        return dataclasses.replace(self, **fields) if fields else self


_FIELDS = frozenset(f.name for f in dataclasses.fields(EvaluationSettings))


def build_uncertainty_settings(
    *,
    sources: str | tuple[str, ...] | list[str],
    tracker_noise_um: float,
    tracker_noise_um_per_m: float,
    encoder_noise_deg: float,
    linear_encoder_noise_um: float,
    independent_model_error: bool = False,
    lambda_range: tuple[float, float] | None = None,
    min_poses: int | None = None,
    subset_size: int | None = None,
    tracker_xyz_m: Sequence[float] | None = None,
    between_session: Any = None,
) -> UncertaintySettings:
    """The sources and noise models of the values a user gives, in the units they are given in.

    Parameters
    ----------
    sources : str or sequence of str
        ``"tracker,encoder"``, ``"all"`` or names (see
        :func:`~robocal_uncertainty.uncertainty.sources.parse_sources`).
    tracker_noise_um, tracker_noise_um_per_m : float
        Tracker MPE a [µm] and b [µm/m] of a + b L (uniform half-width per coordinate).
    encoder_noise_deg, linear_encoder_noise_um : float
        Reading half-width of a revolute joint [deg] and of a prismatic one [µm].
    independent_model_error : bool
        Draw the model error independently from pose to pose (else as a field over the joint
        configurations).
    lambda_range : (float, float) or None
        Range of the ``lambda`` source (scaled units); None: around the optimum.
    min_poses, subset_size : int or None
        Pose counts of the ``n_poses`` and ``pose_choice`` sources; None: the defaults.
    tracker_xyz_m : sequence of 3 float or None
        Tracker position in the base frame [m] (base-frame campaigns); None: the default.
    between_session : BetweenSessions or None
        Between-session component of the ``between_session`` source.

    Raises
    ------
    ConfigError
        Unknown sources, or a value outside its range.
    """
    values = {
        "tracker_noise_um": tracker_noise_um,
        "tracker_noise_um_per_m": tracker_noise_um_per_m,
        "encoder_noise_deg": encoder_noise_deg,
        "linear_encoder_noise_um": linear_encoder_noise_um,
        "independent_model_error": independent_model_error,
        "lambda_range": lambda_range,
        "min_poses": min_poses,
        "subset_size": subset_size,
    }
    return build_source_settings(
        sources=sources, values=values, tracker_xyz_m=tracker_xyz_m, between_session=between_session
    )


def build_source_settings(
    *,
    sources: str | tuple[str, ...] | list[str],
    values: Mapping[str, Any],
    tracker_xyz_m: Sequence[float] | None = None,
    between_session: Any = None,
) -> UncertaintySettings:
    """The sources and their models of the option values of every registered source.

    The command line passes its parsed options, the uncertainty node its parameters (through
    :meth:`~robocal_uncertainty.uncertainty.sources.SourceOption.from_parameters`); each
    source turns its own values into settings
    (:func:`~robocal_uncertainty.uncertainty.sources.source_settings_fields`), so neither
    names a source's settings.

    Parameters
    ----------
    sources : str or sequence of str
        ``"tracker,encoder"``, ``"all"`` or names.
    values : mapping
        Option values by option destination (``tracker_noise_um``, ``lambda_range``, ...), in
        the options' units (µm, degrees); None for an option left unset.
    tracker_xyz_m : sequence of 3 float or None
        Tracker position in the base frame [m] (base-frame campaigns); None: the default.
    between_session : BetweenSessions or None
        Between-session component of the ``between_session`` source.

    Raises
    ------
    ConfigError
        Unknown sources, or a value outside its range.
    """
    extra: dict[str, Any] = {} if tracker_xyz_m is None else {"tracker_xyz": tuple(float(v) for v in tracker_xyz_m)}
    fields = source_settings_fields(values)
    return UncertaintySettings(between_session=between_session, sources=parse_sources(sources), **fields, **extra)  # type: ignore[arg-type]


def build_evaluation_settings(uncertainty: UncertaintySettings, **fields: Any) -> EvaluationSettings:
    """The evaluation settings of `uncertainty` (see :func:`build_uncertainty_settings`) and `fields`.

    The command line (its options) and the uncertainty node (its parameters) both build
    their settings with these two functions, so the same values give the same settings.

    Parameters
    ----------
    uncertainty : UncertaintySettings
    **fields
        The other fields of :class:`EvaluationSettings` (trials, seed, coverage, frame, ...),
        already in SI units and parsed (``trials``: an int or ``"auto"``).

    Raises
    ------
    ConfigError
        A value outside its range.
    TypeError
        A field :class:`EvaluationSettings` does not have.
    """
    return EvaluationSettings(uncertainty=uncertainty, **fields)
