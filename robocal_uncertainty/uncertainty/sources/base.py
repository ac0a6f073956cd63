"""What a source of a calibration Monte Carlo is: its protocol, its context, its batch, its spec.

The types every source module builds on, apart from the registry (:mod:`.registry`) and
the settings (:mod:`.settings`), so a source module imports only these and the registry
imports the source modules: no module of the package imports one that imports it back.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import (
    Distribution,
    IndependentCopies,
    IndependentNormal,
    IndependentRectangular,
    Normal,
    Rectangular,
)

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sources.settings import UncertaintySettings

__all__ = [
    "ADDITIVE_FIELDS",
    "AdditiveSource",
    "NodeParameter",
    "OptionGroup",
    "Source",
    "SourceOption",
    "SourceRole",
    "SourceSpec",
    "TrialBatch",
    "TrialContext",
    "stream_id",
]

Array = NDArray[np.float64]
SourceRole = Literal["lambda", "pose_count", "pose_subset", "model_error", "point_noise", "reading_noise"]
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
        """Add ``deviations`` (shape (n_trials, ...)) to the additive field ``name``.

        The first source to touch a field hands its array over (no copy: a sub-batch of a
        632-pose campaign holds megabytes per field); nothing writes into a batch's fields or
        into a source's drawn values afterwards, a second source makes a new sum.
        """
        current = getattr(self, name)
        setattr(self, name, deviations if current is None else current + deviations)


OptionGroup = Literal["noise", "selection", "model", "session"]


@dataclass(frozen=True)
class NodeParameter:
    """A source setting as a ROS node parameter (the node turns it into its declaration).

    Attributes
    ----------
    name : str
        Parameter name (snake case, the unit in the name where it has one).
    default : bool, int, float or str
        Default; its type is the parameter's type (0 stands for "automatic" where the
        command line's option is unset).
    description : str
        What it is; the node appends `` [unit]``.
    unit : str
        Unit of the value ("" for none).
    low, high : int or float, optional
        Inclusive range (published in the descriptor and enforced).
    """

    name: str
    default: bool | int | float | str
    description: str
    unit: str = ""
    low: float | int | None = None
    high: float | int | None = None


@dataclass(frozen=True)
class SourceOption:
    """A setting of a source as the user gives it: one command-line option and its node parameters.

    The command line builds its option with :meth:`argparse_kwargs`, the uncertainty node
    declares :attr:`parameters`; both are generated from the registry, so a source's
    settings appear in every command and in the node without editing them.

    Attributes
    ----------
    flag : str
        Command-line option, e.g. ``--tracker-noise-um``.
    help : str
        Its help text (argparse; may use ``%(default)s``), the unit included.
    group : {"noise", "selection", "model", "session"}
        Where the option appears: ``noise`` with the instrument models (also in commands that
        simulate or calibrate), ``selection`` and ``model`` with the Monte Carlo options,
        ``session`` in the commands that state for a future session (evaluate).
    unit : str
        Unit the user gives the value in ("" for none).
    type : {float, int, str} or None
        Value type (None for a flag; str for a file).
    default : object
        Default of the option (None: unset, the source chooses).
    nargs : int or None
        Values per option (2 for a range).
    metavar : tuple of str or None
    flag_only : bool
        A switch (``store_true``) without a value.
    parameters : tuple of NodeParameter
        The uncertainty node's parameters for this setting (two for a range); none for an
        option of the command line only (the node leaves it unset).
    """

    flag: str
    help: str
    group: OptionGroup
    unit: str = ""
    type: type | None = None
    default: object = None
    nargs: int | None = None
    metavar: tuple[str, ...] | None = None
    flag_only: bool = False
    parameters: tuple[NodeParameter, ...] = ()

    @property
    def dest(self) -> str:
        """Key of the option's value: the argparse destination (``--min-poses``: ``min_poses``)."""
        return self.flag.lstrip("-").replace("-", "_")

    def from_parameters(self, values: Mapping[str, Any]) -> Any:
        """The option's value, as the command line gives it, from the node's parameter `values`.

        A range (two parameters) of zeros and a count of 0 stand for the option left unset
        (None); otherwise the parameters' values in the option's type.
        """
        if not self.parameters:
            return False if self.flag_only else None
        convert: Callable[[Any], Any] = bool if self.flag_only or self.type is None else self.type
        given = [convert(values[parameter.name]) for parameter in self.parameters]
        if self.nargs is not None:
            return None if all(v == 0 for v in given) else tuple(given)
        if self.default is None and not self.flag_only and given[0] == 0:
            return None
        return given[0]

    def argparse_kwargs(self) -> dict[str, object]:
        """Keyword arguments of ``ArgumentParser.add_argument(self.flag, **kwargs)``."""
        if self.flag_only:
            return {"action": "store_true", "help": self.help}
        kwargs: dict[str, object] = {"type": self.type}
        if self.default is not None:
            kwargs["default"] = self.default
        if self.nargs is not None:
            kwargs["nargs"] = self.nargs
        if self.metavar is not None:
            kwargs["metavar"] = self.metavar
        kwargs["help"] = self.help
        return kwargs


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

    @property
    def draws_by_rows(self) -> bool:
        """Whether ``draw(rng, a)`` then ``draw(rng, b)`` are the rows of ``draw(rng, a + b)``, bit for bit.

        True for the distributions drawn by one uniform or normal fill of the generator, then
        scaled value by value (each value takes the next values of the stream, nothing is
        buffered between calls): a trial block may then draw them sub-batch by sub-batch, in
        arrays that stay in the cache, instead of all its trials at once (hundreds of MB for
        a 632-pose campaign, most of their cost the pages' first touch). False where a call
        draws integers (a buffered 32-bit stream) or multiplies rows by a matrix.
        """
        dist = self.distribution
        if isinstance(dist, IndependentCopies):
            dist = dist.distribution
        return isinstance(dist, (IndependentRectangular, IndependentNormal, Normal, Rectangular))

    def apply(self, values: Array, batch: TrialBatch) -> None:
        start = 0
        for name, shape in self.segments:
            stop = start + math.prod(shape)
            batch.add(name, values[:, start:stop].reshape(values.shape[0], *shape))
            start = stop


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
    role : {"lambda", "pose_count", "pose_subset", "model_error", "point_noise", "reading_noise"} or None
        What the preparation of an evaluation and the sweeps must know about the source,
        so that they never test a source's name: ``lambda`` draws the regularisation
        parameter (its range is prepared; the lambda sweep fixes it), ``pose_count`` draws the
        number of poses and ``pose_subset`` subsets of a fixed size (their pose counts are
        checked and adapted to a small campaign; the equations sweep draws subsets of each
        count), ``model_error`` draws the model error (the model-error field is estimated for
        it), ``point_noise`` and ``reading_noise`` draw the measuring instrument's point errors
        and the joint readings' errors (the pose suggestion weights poses by them). None: none
        of these.
    in_sweeps : bool
        Drawn at every point of the sweeps (the measurement and model noise whose
        uncertainty the sweeps show against lambda and the number of equations).
    options : tuple of SourceOption
        The settings of the source a user sets (command-line options, node parameters),
        with their units, ranges and defaults.
    to_settings : callable, optional
        ``to_settings(values) -> {field: value}``: the :class:`UncertaintySettings` fields
        (SI units) of the option values (keyed by :attr:`SourceOption.dest`, in the options'
        units), so the command line and the node build the settings without naming them.
    """

    name: str
    description: str
    smooth: bool
    build: Callable[[UncertaintySettings, TrialContext], Source]
    role: SourceRole | None = None
    in_sweeps: bool = False
    options: tuple[SourceOption, ...] = ()
    to_settings: Callable[[Mapping[str, Any]], Mapping[str, object]] | None = None

    @property
    def stream_id(self) -> int:
        return stream_id(self.name)
