"""The uncertainty sources of a calibration Monte Carlo, as objects in a registry.

A source is one input of JCGM 101's model: it draws its values for a block of trials
from its own random stream and applies them to a batch of trials (perturbed points,
joint readings, regularisation parameter, pose selection, prediction offsets). Smooth
sources carry their noise model as a :mod:`robocal_uncertainty.montecarlo` distribution,
so the Monte Carlo samples and the GUM variance come from one definition, and they act
additively on named fields of the batch, so the GUM sensitivities follow from the
calibration's linearisation. Each source draws from ``SeedSequence(seed, spawn_key=(block,
stream_id))`` with a stream id fixed by its name: adding or removing a source never
changes another source's draws.

Register a new source with :func:`register_source`; every command, node and report
then lists it.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.simulation import EncoderNoise, TrackerNoise

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.between_sessions import BetweenSessions
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import (
    Distribution,
    Empirical,
    IndependentCopies,
    IndependentNormal,
    IndependentRectangular,
    Rectangular,
)

__all__ = [
    "SOURCES",
    "SOURCE_DESCRIPTIONS",
    "SOURCE_REGISTRY",
    "AdditiveSource",
    "Source",
    "SourceSpec",
    "TrialBatch",
    "TrialContext",
    "UncertaintySettings",
    "build_sources",
    "default_sources",
    "parse_sources",
    "register_source",
    "source_rng",
    "sources_help",
    "stream_id",
]

Array = NDArray[np.float64]
BatchField = Literal["points", "joints", "test_joints", "predictions"]
ADDITIVE_FIELDS: tuple[str, ...] = ("points", "joints", "test_joints", "predictions")


@dataclass(frozen=True, eq=False)
class TrialContext:
    """What the sources of one evaluation need to know about its campaign.

    Attributes
    ----------
    n_poses, n_joints, n_test : int
        Calibration poses, joints, test configurations.
    measurement_dimension : int
        Components of one measurement (3 for a tracker point).
    distances : ndarray, shape (n_poses,) [m]
        Distance of every measured point from the tracker (for the MPE a + b L).
    model_errors : ndarray, shape (n_poses, measurement_dimension) [m]
        Whitened residual draws of the model-adequacy assessment (zeros when adequate).
    lambda_star : float
        Lambda of the calibration (scaled units).
    lambda_range : (float, float) or None
        Range of the ``lambda`` source.
    min_poses, subset_size : int
        Pose counts of the ``n_poses`` and ``pose_choice`` sources.
    rotation_std : ndarray, shape (3,) [rad] or None
        Standard uncertainty of a measured orientation about the measurement frame's x, y, z
        axes (the rotation components 3-5 of a 6-DOF measurement); None for points.
    test_effect_jacobian : ndarray, shape (n_test, 3, k) or None
        Derivative of the predicted tool point w.r.t. the between-session effects (the
        ``between_session`` source); None without a between-session component.
    prismatic : tuple of bool, length n_joints (or empty: all revolute)
        Joints whose reading is a length [m] (their encoder noise is ``linear_half_width``).
    model_error_field : Distribution or None
        The model error drawn jointly over the calibration poses and the test configurations
        (:class:`~robocal_uncertainty.uncertainty.model_error_draws.FieldNormal`: ``e_t`` then
        ``-e_c``); None draws `model_errors` independently from pose to pose.
    """

    n_poses: int
    n_joints: int
    n_test: int
    measurement_dimension: int
    distances: Array
    model_errors: Array
    lambda_star: float
    lambda_range: tuple[float, float] | None
    min_poses: int
    subset_size: int
    rotation_std: Array | None = None
    test_effect_jacobian: Array | None = None
    prismatic: tuple[bool, ...] = ()
    model_error_field: Distribution | None = None

    @property
    def rotation_components(self) -> tuple[int, ...]:
        """Components of a measurement that are rotations (3, 4, 5 for a pose; none for a point)."""
        return (3, 4, 5) if self.rotation_std is not None else ()


@dataclass(eq=False)
class TrialBatch:
    """Working arrays of ``n_trials`` trials that the sources perturb (SI units).

    Additive fields hold deviations and stay None until a source touches them, so an
    unperturbed input costs nothing.

    Attributes
    ----------
    n_trials : int
    points : ndarray, shape (n_trials, n_poses, d) [m] or None
        Deviations of the measured points.
    joints : ndarray, shape (n_trials, n_poses, n_joints) [rad] or None
        Deviations of the campaign's joint readings.
    test_joints : ndarray, shape (n_trials, n_test, n_joints) [rad] or None
        Deviations of the test configurations' joint readings.
    predictions : ndarray, shape (n_trials, n_test, d) [m] or None
        Offsets added to the predicted measurement (measurement frame).
    lambdas : ndarray, shape (n_trials,) or None
        Regularisation parameter per trial; None means the calibration's.
    weights : ndarray, shape (n_trials, n_poses) or None
        0/1 pose selection per trial; None means every pose.
    """

    n_trials: int
    points: Array | None = None
    joints: Array | None = None
    test_joints: Array | None = None
    predictions: Array | None = None
    lambdas: Array | None = None
    weights: Array | None = None

    def add(self, name: str, deviations: Array) -> None:
        """Add ``deviations`` (shape (n_trials, ...)) to the additive field ``name``."""
        current = getattr(self, name)
        setattr(self, name, deviations.copy() if current is None else current + deviations)


@runtime_checkable
class Source(Protocol):
    """One switchable input of the calibration Monte Carlo."""

    @property
    def name(self) -> str:
        """Registry name, e.g. ``"tracker"``."""
        ...

    @property
    def smooth(self) -> bool:
        """True when the output is differentiable in the source (GUM applicable)."""
        ...

    @property
    def distribution(self) -> Distribution | None:
        """Noise model of a smooth source (GUM variance and Monte Carlo samples); else None."""
        ...

    @property
    def segments(self) -> tuple[tuple[str, tuple[int, ...]], ...]:
        """Additive fields of a smooth source and their per-trial shapes, in column order."""
        ...

    def draw(self, rng: np.random.Generator, n: int) -> Array:
        """The source's values for n trials, shape (n, width), from its own stream."""
        ...

    def apply(self, values: Array, batch: TrialBatch) -> None:
        """Perturb ``batch`` with ``values`` (rows of :meth:`draw` for the batch's trials)."""
        ...


@dataclass(frozen=True, eq=False)
class AdditiveSource:
    """A smooth source: values from a distribution, added to fields of the batch.

    Parameters
    ----------
    name : str
    distribution : Distribution
        Its noise model; ``distribution.size`` equals the total size of `segments`.
    segments : tuple of (field, shape)
        The batch fields (points, joints, test_joints, predictions) the value vector is
        split into, in order, with their per-trial shapes.
    """

    name: str
    distribution: Distribution
    segments: tuple[tuple[str, tuple[int, ...]], ...]
    smooth: bool = field(default=True, init=False)

    def __post_init__(self) -> None:
        width = sum(math.prod(shape) for _, shape in self.segments)
        if width != self.distribution.size:
            msg = f"source {self.name!r}: segments hold {width} values, its distribution {self.distribution.size}"
            raise ConfigError(msg)
        unknown = [f for f, _ in self.segments if f not in ADDITIVE_FIELDS]
        if unknown:
            msg = f"source {self.name!r}: unknown batch fields {unknown}; known: {', '.join(ADDITIVE_FIELDS)}"
            raise ConfigError(msg)

    def draw(self, rng: np.random.Generator, n: int) -> Array:
        return np.asarray(self.distribution.sample(rng, n), dtype=np.float64).reshape(n, self.distribution.size)

    def apply(self, values: Array, batch: TrialBatch) -> None:
        start = 0
        for name, shape in self.segments:
            stop = start + math.prod(shape)
            batch.add(name, values[:, start:stop].reshape(values.shape[0], *shape))
            start = stop


@dataclass(frozen=True, eq=False)
class LambdaSource:
    """Regularisation parameter uniform over its valid range (seed Sec. 4.3)."""

    low: float
    high: float
    name: str = "lambda"
    smooth: bool = False
    distribution: None = None
    segments: tuple[tuple[str, tuple[int, ...]], ...] = ()

    def draw(self, rng: np.random.Generator, n: int) -> Array:
        return rng.uniform(self.low, self.high, size=(n, 1))

    def apply(self, values: Array, batch: TrialBatch) -> None:
        batch.lambdas = values[:, 0].copy()


def _random_subsets(rng: np.random.Generator, n: int, n_poses: int) -> Array:
    """Rank of every pose in a uniformly random order, per trial, shape (n, n_poses)."""
    return np.argsort(np.argsort(rng.random((n, n_poses)), axis=1), axis=1).astype(np.float64)


@dataclass(frozen=True, eq=False)
class PoseCountSource:
    """Number of poses used, uniform between a minimum and all (random subsets)."""

    min_poses: int
    n_poses: int
    name: str = "n_poses"
    smooth: bool = False
    distribution: None = None
    segments: tuple[tuple[str, tuple[int, ...]], ...] = ()

    def draw(self, rng: np.random.Generator, n: int) -> Array:
        counts = rng.integers(self.min_poses, self.n_poses + 1, size=n)
        ranks = _random_subsets(rng, n, self.n_poses)
        return (ranks < counts[:, None]).astype(np.float64)

    def apply(self, values: Array, batch: TrialBatch) -> None:
        batch.weights = values.copy() if batch.weights is None else batch.weights * values


@dataclass(frozen=True, eq=False)
class PoseChoiceSource:
    """Choice of poses: random subsets of a fixed size."""

    subset_size: int
    min_poses: int
    n_poses: int
    name: str = "pose_choice"
    smooth: bool = False
    distribution: None = None
    segments: tuple[tuple[str, tuple[int, ...]], ...] = ()

    def draw(self, rng: np.random.Generator, n: int) -> Array:
        return (_random_subsets(rng, n, self.n_poses) < self.subset_size).astype(np.float64)

    def apply(self, values: Array, batch: TrialBatch) -> None:
        if batch.weights is None:
            batch.weights = values.copy()
            return
        weights = batch.weights * values
        # With n_poses on too, the subset of the subset must still identify the model.
        short = weights.sum(axis=1) < self.min_poses
        weights[short] = values[short]
        batch.weights = weights


def _tracker(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    d = ctx.measurement_dimension
    half = np.repeat(settings.tracker_noise.half_width(ctx.distances), d)
    rotations = list(ctx.rotation_components)
    if rotations:
        # Position components only: the orientation noise is the tracker_orientation source.
        per_pose = half.reshape(ctx.n_poses, d)
        per_pose[:, rotations] = 0.0
        half = per_pose.reshape(-1)
    return AdditiveSource("tracker", IndependentRectangular(half), (("points", (ctx.n_poses, d)),))


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
    if any(ctx.prismatic):
        # Revolute readings in rad, prismatic ones in m: one half-width per joint.
        half = np.tile(settings.encoder_noise.half_widths(ctx.prismatic), ctx.n_poses + ctx.n_test)
        return AdditiveSource("encoder", IndependentRectangular(half), segments)
    h = settings.encoder_noise.half_width
    count = (ctx.n_poses + ctx.n_test) * ctx.n_joints
    one = Rectangular(-h, h) if h > 0 else IndependentRectangular([0.0])
    return AdditiveSource("encoder", IndependentCopies(one, count), segments)


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


def _lambda(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    lo, hi = ctx.lambda_range if ctx.lambda_range is not None else (ctx.lambda_star, ctx.lambda_star)
    return LambdaSource(lo, hi)


def _n_poses(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    return PoseCountSource(ctx.min_poses, ctx.n_poses)


def _pose_choice(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    return PoseChoiceSource(ctx.subset_size, ctx.min_poses, ctx.n_poses)


def stream_id(name: str) -> int:
    """Stable 32-bit id of a source name: the last spawn-key element of its stream."""
    return zlib.crc32(name.encode("utf-8"))


@dataclass(frozen=True)
class SourceSpec:
    """A registered source kind.

    Attributes
    ----------
    name : str
        Name on the command line, in node parameters and in reports.
    description : str
        One line for help texts and reports.
    smooth : bool
        GUM applicable (first-order propagation is meaningful).
    build : callable
        ``build(settings, context) -> Source`` for one evaluation.
    """

    name: str
    description: str
    smooth: bool
    build: Callable[[UncertaintySettings, TrialContext], Source]

    @property
    def stream_id(self) -> int:
        return stream_id(self.name)


SOURCE_REGISTRY: dict[str, SourceSpec] = {}


def register_source(spec: SourceSpec) -> None:
    """Add a source kind; its name must be new and its stream id unique.

    Raises
    ------
    ConfigError
        Name already registered, or its stream id collides with another's.
    """
    if spec.name in SOURCE_REGISTRY or spec.name == "all" or not spec.name.isidentifier():
        msg = f"source name {spec.name!r} is taken or not an identifier"
        raise ConfigError(msg)
    if any(other.stream_id == spec.stream_id for other in SOURCE_REGISTRY.values()):
        msg = f"source name {spec.name!r} collides with another source's random stream id; choose another name"
        raise ConfigError(msg)
    SOURCE_REGISTRY[spec.name] = spec


for _spec in (
    SourceSpec("tracker", "laser-tracker noise on every measured point", True, _tracker),
    SourceSpec("encoder", "encoder noise on every joint reading, and on the test configuration", True, _encoder),
    SourceSpec(
        "lambda", "regularisation parameter drawn over its valid range around the L-curve optimum", False, _lambda
    ),
    SourceSpec("n_poses", "number of poses used, drawn between a minimum and all (random subsets)", False, _n_poses),
    SourceSpec("pose_choice", "choice of poses: random subsets of fixed size", False, _pose_choice),
    SourceSpec(
        "residual",
        "model error left after calibration (model inadequacy): a Gaussian field over the joint "
        "configurations (restricted maximum likelihood on the residuals), drawn jointly on the data and "
        "the predictions with --model-error-field; else a residual bootstrap, independent from pose to pose",
        True,
        _residual,
    ),
    SourceSpec(
        "tracker_orientation",
        "laser-tracker orientation noise on every measured orientation (6-DOF campaigns; normal, "
        "the measurement's per-axis rotation std; zero for points)",
        True,
        _tracker_orientation,
    ),
):
    register_source(_spec)


class _Descriptions(Mapping[str, str]):
    """Live view name -> description of the registry (sources registered later included)."""

    def __getitem__(self, key: str) -> str:
        return SOURCE_REGISTRY[key].description

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(SOURCE_REGISTRY)

    def __len__(self) -> int:
        return len(SOURCE_REGISTRY)


SOURCE_DESCRIPTIONS: Mapping[str, str] = _Descriptions()
SOURCES: tuple[str, ...] = tuple(SOURCE_REGISTRY)
"""The built-in sources, in registry order."""


def source_rng(block_rng: np.random.Generator, stream: int) -> np.random.Generator:
    """Generator of one source in one block: ``SeedSequence(seed, spawn_key=(block, stream))``.

    Derived from the block generator's own SeedSequence, so a worker needs nothing more
    than the engine gives it.
    """
    bit_generator = block_rng.bit_generator
    seq = getattr(bit_generator, "seed_seq", None) or bit_generator._seed_seq  # type: ignore[attr-defined]  # numpy < 1.25
    return np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, int(stream))))


def sources_help() -> str:
    """``"tracker, encoder, ... or all"`` from the registry, for help texts and node parameters."""
    return f"{', '.join(SOURCE_REGISTRY)}, or all"


def build_sources(settings: UncertaintySettings, context: TrialContext) -> tuple[Source, ...]:
    """The enabled sources of `settings` for one evaluation, in registry order."""
    return tuple(SOURCE_REGISTRY[name].build(settings, context) for name in SOURCE_REGISTRY if name in settings.sources)


def parse_sources(text: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Parse ``"tracker,encoder"`` or ``"all"`` into a tuple of registered source names.

    Raises
    ------
    ConfigError
        Unknown or empty source names.
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    names = [s.strip() for s in items if s.strip()]
    known = tuple(SOURCE_REGISTRY)
    if names == ["all"]:
        return known
    unknown = [s for s in names if s not in SOURCE_REGISTRY]
    if unknown:
        msg = f"unknown uncertainty source(s) {unknown}; known: {', '.join(known)} or 'all'"
        raise ConfigError(msg)
    if not names:
        msg = f"no uncertainty source given; known: {', '.join(known)}"
        raise ConfigError(msg)
    return tuple(dict.fromkeys(names))


def default_sources(measures_orientation: bool = False) -> tuple[str, ...]:
    """The default sources of every command, node and API call: the validated statement.

    ``tracker``, ``encoder`` and ``residual`` (the model error the adequacy test finds; it
    adds nothing when the residuals are consistent with the stated noise), plus
    ``tracker_orientation`` when the campaign measures orientations (a 6-DOF tracker).
    This is the set ``validate`` checks against held-out poses; leaving ``residual`` out
    states only the instrument noise, 5-8 times below the validated u on the UR10 series.

    Parameters
    ----------
    measures_orientation : bool
        The campaign's measurement type holds an orientation.

    Returns
    -------
    tuple of str, in registry order.
    """
    names = ("tracker", "encoder", "residual") + (("tracker_orientation",) if measures_orientation else ())
    return tuple(name for name in SOURCE_REGISTRY if name in names)


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
        max(ceil(40/3), ceil(1.5 n_identifiable / 3)) as the seed's 40 equations.
    subset_size : int or None
        Pose count for the ``pose_choice`` source; None means round(33/53 n_poses),
        the seed's ratio.
    tracker_xyz : (float, float, float)
        Tracker position in the robot base frame [m], for MPE distances when the campaign
        is in the base frame.
    gauss_newton_iterations : int
        Maximum re-identification iterations per trial (warm-started at the calibration).
    between_session : BetweenSessions or None
        Between-session component for the ``between_session`` source
        (:mod:`robocal_uncertainty.uncertainty.between_sessions`).
    jacobian : {"frozen", "exact"}
        ``frozen``: chord iterations with the calibration's Jacobian (fast, default);
        ``exact``: Gauss-Newton with each trial's own Jacobian (reference).
    model_error : {"independent", "field"}
        How the ``residual`` source draws the model error: ``independent`` (default), a residual
        bootstrap independent from pose to pose; ``field``, a Gaussian field correlated over the
        joint configurations, drawn jointly over the calibration poses and the test
        configurations (:mod:`~robocal_uncertainty.uncertainty.model_error_draws`). Not the
        default: on the UR10 series D with 53 training poses it states held-out poses too
        narrow (``benchmarks/study_model_error_field.py``).
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
    model_error: Literal["field", "independent"] = "independent"

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


# Sources in their own modules register themselves on import.
from robocal_uncertainty.uncertainty import between_sessions as _between_sessions  # noqa: F401
