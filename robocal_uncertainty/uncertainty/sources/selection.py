"""Selection sources: the regularisation parameter and the poses a calibration uses.

Not smooth (GUM does not apply): they change which problem is solved, not its data, and
act on the batch's ``lambdas`` and ``weights`` instead of adding to a field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from robocal_uncertainty.uncertainty.sources.base import (
    Array,
    NodeParameter,
    Source,
    SourceOption,
    SourceSpec,
    TrialBatch,
    TrialContext,
)

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sources.settings import UncertaintySettings

__all__ = ["LAMBDA", "N_POSES", "POSE_CHOICE", "LambdaSource", "PoseChoiceSource", "PoseCountSource"]


@dataclass(frozen=True, eq=False)
class LambdaSource:
    """Regularisation parameter uniform over its valid range (reference paper Sec. 4.3)."""

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


def _lambda(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    lo, hi = ctx.lambda_range if ctx.lambda_range is not None else (ctx.lambda_star, ctx.lambda_star)
    return LambdaSource(lo, hi)


def _n_poses(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    return PoseCountSource(ctx.min_poses, ctx.n_poses)


def _pose_choice(settings: UncertaintySettings, ctx: TrialContext) -> Source:
    return PoseChoiceSource(ctx.subset_size, ctx.min_poses, ctx.n_poses)


def _lambda_settings(values: Mapping[str, Any]) -> Mapping[str, object]:
    given = values["lambda_range"]
    return {"lambda_range": None if given is None else (given[0], given[1])}


LAMBDA = SourceSpec(
    "lambda",
    "regularisation parameter drawn over its valid range around the L-curve optimum",
    False,
    _lambda,
    role="lambda",
    to_settings=_lambda_settings,
    options=(
        SourceOption(
            "--lambda-range",
            "range of lambda for the 'lambda' source (default lambda*/5 .. 5 lambda*)",
            "selection",
            "dimensionless",
            float,
            nargs=2,
            metavar=("LOW", "HIGH"),
            parameters=(
                NodeParameter(
                    "lambda_range_low",
                    0.0,
                    "Low end of lambda for the 'lambda' source; 0 and 0 = lambda*/5 .. 5 lambda*",
                    "dimensionless",
                    0.0,
                    1e12,
                ),
                NodeParameter(
                    "lambda_range_high", 0.0, "High end of lambda for the 'lambda' source", "dimensionless", 0.0, 1e12
                ),
            ),
        ),
    ),
)
N_POSES = SourceSpec(
    "n_poses",
    "number of poses used, drawn between a minimum and all (random subsets)",
    False,
    _n_poses,
    role="pose_count",
    to_settings=lambda values: {"min_poses": values["min_poses"]},
    options=(
        SourceOption(
            "--min-poses",
            "smallest pose count of the 'n_poses' source (default: 40 equations or 1.5 x the identifiable "
            "parameters, whichever is more; lowered for a smaller campaign)",
            "selection",
            "poses",
            int,
            parameters=(
                NodeParameter(
                    "min_poses", 0, "Smallest pose count of the 'n_poses' source; 0 = automatic", "poses", 0, 100_000
                ),
            ),
        ),
    ),
)
POSE_CHOICE = SourceSpec(
    "pose_choice",
    "choice of poses: random subsets of fixed size",
    False,
    _pose_choice,
    role="pose_subset",
    to_settings=lambda values: {"subset_size": values["subset_size"]},
    options=(
        SourceOption(
            "--subset-size",
            "pose count of the 'pose_choice' source (default: 33/53 of the campaign's poses)",
            "selection",
            "poses",
            int,
            parameters=(
                NodeParameter(
                    "subset_size", 0, "Pose count of the 'pose_choice' source; 0 = automatic", "poses", 0, 100_000
                ),
            ),
        ),
    ),
)
