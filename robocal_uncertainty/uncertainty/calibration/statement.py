"""The uncertainty statement of a calibration Monte Carlo's trials.

Summaries, coverage regions and the GUM check per test configuration, the orientation
statement, and the warnings a reader needs beside the numbers: a regularisation bias the
interval does not cover, too few trials for the coverage asked, an adaptive run that stopped
at its cap.
"""

from __future__ import annotations

import numpy as np

from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.kernels import resolve_backend
from robocal_uncertainty.montecarlo.engine import TrialsResult
from robocal_uncertainty.montecarlo.region import EllipsoidalRegion, coverage_region
from robocal_uncertainty.montecarlo.summary import summarize
from robocal_uncertainty.uncertainty.calibration.gum import gum_poses, regularisation_bias
from robocal_uncertainty.uncertainty.calibration.orientation import orientation_uncertainty
from robocal_uncertainty.uncertainty.calibration.preparation import Prepared
from robocal_uncertainty.uncertainty.calibration.results import N_AXES, CalibrationUncertainty, PoseUncertainty
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings
from robocal_uncertainty.uncertainty.statement_check import gum_disagreements, too_few_trials_note

__all__ = ["state_uncertainty"]

# A bias beyond half the standard uncertainty lowers a 95 % interval's coverage below ~92 %.
_BIAS_WARN_RATIO = 0.5


def state_uncertainty(
    prep: Prepared, ev: EvaluationSettings, result: TrialsResult, *, per_pose: bool = False
) -> CalibrationUncertainty:
    """The uncertainty statement of the trials `result` (a ``run_trials`` result); `per_pose` as
    for :func:`~robocal_uncertainty.uncertainty.calibration.evaluation.evaluate_uncertainty`."""
    calibration = prep.calibration
    model = calibration.model
    test_q = prep.test_joints
    dim = N_AXES
    n_test = test_q.shape[0]
    k = prep.problem.estimated.size
    # Positions and parameters: the same columns (and numbers) with or without orientation.
    samples = result.samples[:, : dim * n_test + k]
    summary = summarize(samples, ev.coverage)
    gum = gum_poses(prep, summary, ev.coverage, ev.n_dig, per_pose=per_pose)
    orientations = (
        orientation_uncertainty(prep, result.samples, summary, ev.coverage, ev.n_dig, per_pose=per_pose)
        if ev.orientation
        else [None] * n_test
    )
    poses = []
    warns: list[str] = list(calibration.warnings)
    for i in range(n_test):
        cols = slice(dim * i, dim * (i + 1))
        axes = summary.outputs[cols]
        region: EllipsoidalRegion | None = None
        try:
            region = coverage_region(result.samples[:, cols], ev.coverage) if not per_pose else None
        except (InputError, ConfigError) as err:
            warns.append(f"test configuration {i}: no coverage region ({err})")
        poses.append(
            PoseUncertainty(
                joint_positions=test_q[i],
                mean=np.array([a.estimate for a in axes]),
                covariance=summary.covariance[cols, cols],
                axes=tuple(axes),
                region=region,
                gum=gum[i],
                orientation=orientations[i],
            )
        )
    warns += _bias_warnings(prep, poses)
    few = None if result.adaptive is not None else too_few_trials_note(result.n_trials, ev.coverage)
    if few is not None:
        warns.append(few)
    if result.adaptive is not None and not result.adaptive.converged:
        warns.append(
            f"adaptive Monte Carlo stopped at max_trials={ev.max_trials} before reaching "
            f"the numerical tolerance of {ev.n_dig} significant digits"
        )
    return CalibrationUncertainty(
        poses=tuple(poses),
        parameter_names=tuple(model.layout.names[j] for j in prep.problem.estimated),
        parameters=tuple(summary.outputs[dim * n_test :]),
        calibration=calibration,
        settings=ev.uncertainty,
        coverage_probability=ev.coverage,
        n_trials=result.n_trials,
        seed=ev.seed,
        block_size=ev.block_size,
        adaptive=result.adaptive,
        samples=samples,
        lambda_star=calibration.lambda_,
        lambda_range=prep.lambda_range,
        frame=ev.frame,  # type: ignore[arg-type]
        frame_id=prep.frame_id,
        model_adequacy=prep.adequacy,
        warnings=tuple(warns),
        rotation_samples=result.samples[:, dim * n_test + k :] if ev.orientation else None,
        not_converged=gum_disagreements(poses),
        backend=resolve_backend(ev.backend),
        model_error_field=prep.model_error_field,
    )


def _bias_warnings(prep: Prepared, poses: list[PoseUncertainty]) -> list[str]:
    """Warnings for test configurations whose regularisation bias the interval does not cover."""
    warns = []
    bias = regularisation_bias(prep)
    for i, pose in enumerate(poses):
        u = np.array([a.standard_uncertainty for a in pose.axes])
        ratio = np.where(u > 0, np.abs(bias[i]) / np.where(u > 0, u, 1.0), 0.0)
        j = int(np.argmax(ratio))
        if ratio[j] > _BIAS_WARN_RATIO:
            warns.append(
                f"test configuration {i}: regularisation (lambda = {prep.calibration.lambda_:.3g}) shifts the "
                f"calibrated position by about {bias[i, j] * 1e6:.3g} um along {'xyz'[j]}, "
                f"{ratio[j]:.2g} times its standard uncertainty, and the interval does not contain "
                "this bias: measure more poses, or use a smaller --lambda"
            )
    return warns
