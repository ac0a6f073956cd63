"""Everything that determines a calibration's uncertainty evaluation, and its one Monte Carlo call.

:class:`EvaluationOptions` is what the command line parses, the nodes read from their
parameters and the tests construct; :func:`evaluate_campaign` turns it into the one call
of :func:`~robocal_uncertainty.uncertainty.calibration.evaluation.evaluate_uncertainty`. The
application service :func:`robocal_uncertainty.app.evaluate` adds the calibration, the
budget and the sweeps on top; this module is below it so that the ROS-free pipeline can
hold the options too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.calibration import (
    CalibrationUncertainty,
    EvaluationSettings,
    evaluate_uncertainty,
)
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

__all__ = ["EvaluationOptions", "Progress", "evaluate_campaign"]

Array = NDArray[np.float64]
Progress = Callable[[int, "int | None"], None]
"""``progress(done, target)``: trials done so far and the target (None while adaptive)."""


def _positive_int(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        msg = f"{name} must be a positive integer, got {value!r}"
        raise ConfigError(msg)


@dataclass(frozen=True)
class EvaluationOptions:
    """Everything that determines a calibration and its uncertainty result.

    Parameters
    ----------
    lambda_ : {"auto", "gcv"} or float
        Lambda method of the identification (see
        :func:`~robocal_uncertainty.core.identification.identify`).
    uncertainty : UncertaintySettings
        Sources and noise models of the Monte Carlo.
    test_joints : ndarray, shape (n_test, n_joints) [rad], optional
        Configurations at which the tool position uncertainty is evaluated; required by
        :func:`evaluate_campaign`.
    trials : int or "auto"
        Number of Monte Carlo trials, or the adaptive procedure.
    seed : int
        Root seed of the Monte Carlo (and of every budget run and sweep point).
    coverage : float
        Coverage probability p in (0, 1).
    n_dig, max_trials, block_size : int
        Adaptive-procedure digits, its trial cap, and trials per random stream (see
        :func:`~robocal_uncertainty.uncertainty.calibration.evaluation.evaluate_uncertainty`).
    output_frame : {"measurement", "base"}
        Frame of the output positions (the frame of the campaign's points by default).
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
    backend : {"numpy", "numba", "cupy", "auto"}
        Trial kernels of every Monte Carlo run (:mod:`robocal_uncertainty.kernels`); the
        result is the same to rounding whichever runs it.

    Raises
    ------
    ConfigError
        Test joints not finite or not 2-D; a trial count that is not a positive integer.
    """

    lambda_: str | float = "auto"
    uncertainty: UncertaintySettings = field(default_factory=UncertaintySettings)
    test_joints: Array | None = None
    trials: int | str = 10_000
    seed: int = 0
    coverage: float = 0.95
    n_dig: int = 2
    max_trials: int = 2_000_000
    block_size: int = 10_000
    output_frame: str = "measurement"
    accept_unconverged: bool = False
    budget: bool = False
    budget_trials: int = 2_000
    sweeps: bool = False
    sweep_trials: int = 300
    backend: str = "numpy"

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
            _positive_int("trials", self.trials)
        for name in ("max_trials", "budget_trials", "sweep_trials"):
            _positive_int(name, getattr(self, name))

    def evaluation_settings(self) -> EvaluationSettings:
        """The settings of the one Monte Carlo evaluation these options ask for."""
        return EvaluationSettings(
            uncertainty=self.uncertainty,
            lambda_=self.lambda_,
            trials=self.trials,
            coverage=self.coverage,
            seed=self.seed,
            n_dig=self.n_dig,
            max_trials=self.max_trials,
            block_size=self.block_size,
            frame=self.output_frame,
            backend=self.backend,
        )


def evaluate_campaign(
    model: RobotModel,
    campaign: Campaign,
    options: EvaluationOptions,
    *,
    calibration: IdentificationResult | None = None,
    workers: int = 1,
    progress: Progress | None = None,
    executor: Any | None = None,
) -> CalibrationUncertainty:
    """Monte Carlo uncertainty of `campaign` as set by `options` (the one call from options).

    Parameters
    ----------
    model : RobotModel
        Nominal model.
    campaign : Campaign
    options : EvaluationOptions
        Must have ``test_joints``.
    calibration : IdentificationResult, optional
        ``identify(model, campaign, lambda_=options.lambda_)`` if already computed; it is
        computed the same way when omitted, so the result does not depend on it.
    workers, progress, executor
        Passed through; they never change the result. `executor` is forwarded only when
        given (a ``concurrent.futures.Executor``-like object).

    Raises
    ------
    ConfigError
        No test joints, or invalid options.
    """
    if options.test_joints is None:
        raise ConfigError("no test joint configurations given for the uncertainty evaluation")
    return evaluate_uncertainty(
        model,
        campaign,
        options.test_joints,
        options.evaluation_settings(),
        calibration=calibration,
        workers=workers,
        progress=progress,
        executor=executor,
    )
