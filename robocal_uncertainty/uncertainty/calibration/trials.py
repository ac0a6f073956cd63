"""The trial block of a calibration Monte Carlo: perturb, re-identify, evaluate.

A block is a picklable callable ``trials(rng, n)``, the model function the engine
(:func:`~robocal_uncertainty.montecarlo.engine.run_trials`) runs in independent seeded
streams, so the result is the same whatever the chunk size or the number of workers.

Orientation (3 extra columns per test configuration): a trial stores the rotation vector
``log(R_trial R_cal^T)`` [rad] of its tool rotation relative to the calibrated one, i.e. a
rotation about the **fixed x, y, z axes of the output frame** (the ROS convention of the
orientation block of ``geometry_msgs/PoseWithCovariance``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import forward_points, forward_poses
from robocal_uncertainty.core.rotation import rotation_log
from robocal_uncertainty.kernels import ToolPredictor
from robocal_uncertainty.montecarlo.streams import source_generator
from robocal_uncertainty.uncertainty.calibration.results import N_AXES
from robocal_uncertainty.uncertainty.reidentification import BatchProblem, ChordSolver, reidentify_batch
from robocal_uncertainty.uncertainty.sources import Source, TrialBatch, stream_id

__all__ = ["CalibrationTrials"]

Array = NDArray[np.float64]
_SUB_BATCH = 256
"""Trials re-identified at once. Fixed: BLAS rounding may depend on the number of rows, so
the split of a block must never depend on a user setting."""
_TEST_ELEMENTS = 16_384
"""Trials x test configurations evaluated at once after the re-identification (memory bound)."""


@dataclass(frozen=True, eq=False)
class CalibrationTrials:
    """Picklable trial block: perturb, re-identify, evaluate at the test configurations.

    Every source draws its values for the block from its own stream (see
    :func:`~robocal_uncertainty.montecarlo.streams.source_generator`); the block's values are
    then applied and re-identified in fixed sub-batches.
    """

    problem: BatchProblem
    x_hat: Array
    joint_positions: Array
    points: Array
    test_joints: Array
    drop_base: bool
    output_rotation: Array
    lambda_star: float
    sources: tuple[Source, ...]
    gauss_newton_iterations: int
    solver: ChordSolver | None = None
    reference_rotations: Array | None = None
    test_predictor: ToolPredictor | None = None

    @property
    def orientation(self) -> bool:
        """Whether trial rows end with the rotation deviations of every test configuration."""
        return self.reference_rotations is not None

    @property
    def n_outputs(self) -> int:
        """Columns of a trial row: x, y, z per test configuration, the parameters, then (with
        orientation) rx, ry, rz per test configuration [rad], ``log(R_trial R_ref^T)``."""
        n_rot = N_AXES * self.test_joints.shape[0] if self.orientation else 0
        return int(N_AXES * self.test_joints.shape[0] + self.x_hat.size + n_rot)

    def __call__(self, rng: np.random.Generator, n: int) -> Array:
        """Model values of n trials, shape (n, d n_test + k)."""
        # Every source draws from its own stream, so a source's values depend on the block and
        # the source alone; the sub-batches below only bound memory. A source whose draws are
        # the same row by row (draws_by_rows) draws each sub-batch's rows when it is applied;
        # the others draw the whole block first.
        streams = [source_generator(rng, stream_id(source.name)) for source in self.sources]
        values: list[Array | np.random.Generator] = [
            stream if getattr(source, "draws_by_rows", False) else source.draw(stream, n)
            for source, stream in zip(self.sources, streams)
        ]
        n_test = self.test_joints.shape[0]
        k = self.x_hat.size
        out = np.empty((n, self.n_outputs))
        params, qt_dev, pred = self._reidentify(values, n)
        out[:, N_AXES * n_test : N_AXES * n_test + k] = params[:, self.problem.estimated]
        if self.drop_base:
            # Positions in the robot base frame: the identified base does not enter.
            b0 = self.problem.layout.base_index
            params[:, b0 : b0 + 6] = 0.0
        self._evaluate_tests(params, qt_dev, pred, out)
        return out

    def _reidentify(
        self, values: list[Array | np.random.Generator], n: int
    ) -> tuple[Array, Array | None, Array | None]:
        """Apply the drawn `values` (or draw from a source's generator) and re-identify, in fixed sub-batches.

        Returns the full parameter vector of every trial, shape (n, n_params), and the
        test-joint deviations and prediction offsets the sources set (None when none did).
        """
        params = np.empty((n, self.problem.start.size))
        test_deviations: list[Array] = []
        predictions: list[Array] = []
        for lo_i in range(0, n, _SUB_BATCH):
            sl = slice(lo_i, min(n, lo_i + _SUB_BATCH))
            t = sl.stop - sl.start
            batch = TrialBatch(n_trials=t)
            for source, value in zip(self.sources, values):
                source.apply(source.draw(value, t) if isinstance(value, np.random.Generator) else value[sl], batch)
            # Every source perturbs the measured points with zero-mean errors, so the trials
            # stay centred on the calibration.
            # Source deviations are in the residual coordinates of the measurement type.
            lambdas = batch.lambdas if batch.lambdas is not None else np.full(t, self.lambda_star)
            if self.solver is not None:
                # The solver adds the errors (a compiled one inside its kernel, without copies).
                measured = (
                    self.points[None]
                    if batch.points is not None
                    else np.broadcast_to(self.points, (t, *self.points.shape))
                )
                x, _ = self.solver.solve(
                    self.joint_positions,
                    measured,
                    batch.weights,
                    lambdas,
                    self.x_hat,
                    deviations=batch.points,
                    reading_errors=batch.joints,
                )
            else:
                x = self._gauss_newton(batch, lambdas)
            params[sl] = self.problem.parameters(x)
            if batch.test_joints is not None:
                test_deviations.append(batch.test_joints)
            if batch.predictions is not None:
                predictions.append(batch.predictions)
        qt_dev = np.concatenate(test_deviations) if test_deviations else None
        pred = np.concatenate(predictions) if predictions else None
        return params, qt_dev, pred

    def _gauss_newton(self, batch: TrialBatch, lambdas: Array) -> Array:
        """The exact batched re-identification of one sub-batch (no chord solver)."""
        t = batch.n_trials
        q = self.joint_positions[None] + batch.joints if batch.joints is not None else self.joint_positions
        pts = (
            self.problem.measurement.perturb(self.points[None], batch.points)
            if batch.points is not None
            else np.broadcast_to(self.points, (t, *self.points.shape))
        )
        x, _ = reidentify_batch(
            self.problem,
            q,
            np.ascontiguousarray(pts),
            batch.weights,
            lambdas,
            self.x_hat,
            iterations=self.gauss_newton_iterations,
        )
        return x

    def _evaluate_tests(self, params: Array, qt_dev: Array | None, pred: Array | None, out: Array) -> None:
        """Fill the position (and rotation) columns of `out` at the test configurations.

        The whole block at once, in slices of a bounded size: every operation here is per
        trial (elementwise, or a 3x3 product per trial), so the values do not depend on the
        slices, and the per-call overhead is paid once per slice instead of once per sub-batch.
        """
        dim = N_AXES
        n = params.shape[0]
        n_test = self.test_joints.shape[0]
        k = self.x_hat.size
        step = max(_SUB_BATCH, _TEST_ELEMENTS // n_test)
        for lo_i in range(0, n, step):
            sl = slice(lo_i, min(n, lo_i + step))
            t = sl.stop - sl.start
            qt = self.test_joints[None] + qt_dev[sl] if qt_dev is not None else self.test_joints
            if self.reference_rotations is None:
                if self.test_predictor is not None:
                    pos = self.test_predictor(params[sl], qt)
                else:
                    pos = forward_points(self.problem.layout, params[sl], qt)
            else:
                if self.test_predictor is not None:
                    values = self.test_predictor.poses(params[sl], qt)
                    pos, rot = values[..., :dim], values[..., dim:].reshape(*values.shape[:-1], dim, dim)
                else:
                    pos, rot = forward_poses(self.problem.layout, params[sl], qt)
                # Deviation about the fixed axes of the output frame: exp([d]x) = R R_ref^T.
                dev = rotation_log(rot @ np.swapaxes(self.reference_rotations, -1, -2))
                if pred is not None and pred.shape[-1] == 2 * dim:
                    # 6-DOF model errors: their rotation part (small) moves the orientation.
                    dev = dev + pred[sl, :, dim:] @ self.output_rotation.T
                out[sl, dim * n_test + k :] = dev.reshape(t, dim * n_test)
            if pred is not None:
                # Row-vector form of R_out e: model errors live in the measurement frame
                # (their position part for 6-DOF measurements).
                pos = pos + pred[sl, :, :dim] @ self.output_rotation.T
            out[sl, : dim * n_test] = pos.reshape(t, dim * n_test)
