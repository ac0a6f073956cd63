"""The numba backend's compiled re-identification against the numpy chord iteration.

:meth:`ChordSolver.solve` hands its whole iteration to the numba kernel (first-order step,
then exact steps with the chain walked per trial, each trial stopping by its own rule). Here
the two are compared directly on sub-batches, for what a trial block can pass: readings per
trial or shared, pose weights (subsets, one normal matrix per trial), per-trial lambdas, point
and 6-DOF measurements, a free base (the Schur complement) or none; and the cases the kernel
hands back to the numpy iteration (a residual rotation near pi).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.core.urdf_model import load_urdf, robot_model_from_urdf
from robocal_uncertainty.kernels import NumbaBackend
from robocal_uncertainty.kernels.predictors import CompiledMeasurement
from robocal_uncertainty.uncertainty import UncertaintySettings, prepare_calibration_trials

pytestmark = pytest.mark.skipif(not NumbaBackend().available(), reason="numba is not installed (extra 'fast')")
ROOT = Path(__file__).resolve().parents[2]


def _solvers(layout: str, six_dof: bool, frame: str) -> tuple[object, object, object]:
    """The numba solver, the numpy one (the numpy backend's predictor) and the trial block."""
    if layout.endswith(".urdf"):
        model = robot_model_from_urdf(load_urdf(ROOT / "test" / "data" / "urdf" / layout), None, None)
    else:
        model = load_robot_model(resolve_robot_config(layout))
    settings = SimulationSettings(n_poses=25, frame=frame, orientation_std=1e-4 if six_dof else None)  # type: ignore[arg-type]
    campaign = simulate_campaign(model, settings, seed=7).campaign
    calibration = identify(model, campaign)
    test_q = campaign.joint_positions[:1]
    blocks = {
        name: prepare_calibration_trials(
            model,
            campaign,
            test_q,
            settings=UncertaintySettings(sources=("tracker", "encoder")),
            calibration=calibration,
            backend=name,
        )
        for name in ("numpy", "numba")
    }
    return blocks["numba"].solver, blocks["numpy"].solver, blocks["numba"]


def _inputs(trials: object, n: int, rng: np.random.Generator, six_dof: bool) -> tuple[np.ndarray, np.ndarray]:
    q0 = trials.joint_positions  # type: ignore[attr-defined]
    values = trials.points  # type: ignore[attr-defined]
    q = q0 + rng.uniform(-2e-5, 2e-5, (n, *q0.shape))
    measurement = trials.problem.measurement  # type: ignore[attr-defined]
    dim = measurement.dimension
    errors = rng.normal(0.0, 1e-5, (n, values.shape[0], dim))
    if six_dof:
        errors[..., 3:] = rng.normal(0.0, 1e-4, (n, values.shape[0], 3))
    return q, measurement.perturb(values[None], errors)


def _assert_same_parameters(trials: object, x: np.ndarray, want: np.ndarray) -> None:
    """The parameters (m, rad) agree to 1e-12 of their value (of 1 m or 1 rad for those near
    zero, as in the trial-block test) and to 1e-9 of how far the trials moved them."""
    problem = trials.problem  # type: ignore[attr-defined]
    got_p, want_p = problem.parameters(x), problem.parameters(want)
    start = problem.parameters(np.broadcast_to(trials.x_hat, want.shape))  # type: ignore[attr-defined]
    diff = np.abs(got_p - want_p)
    scale = np.maximum(np.abs(want_p), 1.0)
    assert (diff <= 1e-12 * scale).all(), (diff / scale).max()
    moved = np.abs(want_p - start).max()
    assert moved > 1e-7  # the trials moved: the comparison can fail
    assert diff.max() <= 1e-9 * moved, diff.max() / moved


@pytest.mark.parametrize(
    ("layout", "six_dof", "frame"),
    [
        ("paper_arm", False, "tracker"),  # free base: Schur complement
        ("paper_arm", False, "base"),  # no free parameter
        ("paper_arm", True, "tracker"),
        ("rail_arm.urdf", False, "tracker"),  # prismatic joint
        ("ur10.urdf", True, "base"),  # URDF mount
    ],
)
@pytest.mark.parametrize("weighted", [False, True])
def test_compiled_iteration_equals_numpy(layout: str, six_dof: bool, frame: str, weighted: bool) -> None:
    compiled, reference, trials = _solvers(layout, six_dof, frame)
    rng = np.random.default_rng(4)
    n = 37
    q, values = _inputs(trials, n, rng, six_dof)
    lambdas = trials.lambda_star * rng.uniform(0.5, 2.0, n)  # type: ignore[attr-defined]
    weights = None
    if weighted:
        weights = (rng.uniform(size=(n, q.shape[1])) < 0.8).astype(np.float64)
        weights[:, :12] = 1.0  # enough poses to identify every parameter
    x_hat = trials.x_hat  # type: ignore[attr-defined]
    assert isinstance(compiled.predictor, CompiledMeasurement)  # type: ignore[attr-defined]
    kernel = compiled.predictor.solve_chord  # type: ignore[attr-defined]
    for readings in (q, trials.joint_positions):  # type: ignore[attr-defined]
        direct = kernel(compiled, readings, values, weights, lambdas, x_hat, max_iterations=6, relative_tolerance=1e-3)
        assert direct is not None  # the kernel ran every trial itself
        x, done = compiled.solve(readings, values, weights, lambdas, x_hat)  # type: ignore[attr-defined]
        want, want_done = reference.solve(readings, values, weights, lambdas, x_hat)  # type: ignore[attr-defined]
        np.testing.assert_array_equal(x, direct[0])
        assert done == want_done
        _assert_same_parameters(trials, x, want)
        # A trial alone gives the same bits as in its batch.
        alone = kernel(
            compiled,
            readings if readings.ndim == 2 else readings[5:6],
            values[5:6],
            None if weights is None else weights[5:6],
            lambdas[5:6],
            x_hat,
            max_iterations=6,
            relative_tolerance=1e-3,
        )
        np.testing.assert_array_equal(alone[0], direct[0][5:6])


def test_rotation_near_pi_is_handed_back_to_numpy() -> None:
    """A residual rotation near pi (where the numpy residual switches formula): the kernel
    declines the sub-batch and the numpy iteration solves it; the result is the numpy one."""
    compiled, reference, trials = _solvers("paper_arm", True, "tracker")
    rng = np.random.default_rng(5)
    q, values = _inputs(trials, 4, rng, True)
    errors = np.zeros((4, values.shape[1], 6))
    errors[2, 3, 3] = 3.1  # one pose of one trial turned by 3.1 rad
    values = trials.problem.measurement.perturb(values, errors)  # type: ignore[attr-defined]
    lambdas = np.full(4, trials.lambda_star)  # type: ignore[attr-defined]
    kernel = compiled.predictor.solve_chord  # type: ignore[attr-defined]
    assert kernel(compiled, q, values, None, lambdas, trials.x_hat, max_iterations=6, relative_tolerance=1e-3) is None  # type: ignore[attr-defined]
    x, _ = compiled.solve(q, values, None, lambdas, trials.x_hat)  # type: ignore[attr-defined]
    numpy_walk = dataclasses.replace(compiled, predictor=reference.predictor)  # type: ignore[call-overload]
    want, _ = numpy_walk.solve(q, values, None, lambdas, trials.x_hat)  # type: ignore[attr-defined]
    _assert_same_parameters(trials, x, want)


def test_shared_measured_values_and_readings() -> None:
    """A block without a tracker source passes every trial the same measured values (a broadcast
    view) and, without an encoder source, the same readings: the kernel reads them once."""
    compiled, reference, trials = _solvers("paper_arm", False, "tracker")
    n = 9
    values = np.broadcast_to(trials.points, (n, *trials.points.shape))  # type: ignore[attr-defined]
    q = trials.joint_positions + np.random.default_rng(6).uniform(-2e-5, 2e-5, (n, *trials.joint_positions.shape))  # type: ignore[attr-defined]
    lambdas = np.full(n, trials.lambda_star)  # type: ignore[attr-defined]
    kernel = compiled.predictor.solve_chord  # type: ignore[attr-defined]
    for readings in (q, trials.joint_positions):  # type: ignore[attr-defined]
        direct = kernel(
            compiled, readings, values, None, lambdas, trials.x_hat, max_iterations=6, relative_tolerance=1e-3
        )  # type: ignore[attr-defined]
        assert direct is not None
        want, _ = reference.solve(readings, values, None, lambdas, trials.x_hat)  # type: ignore[attr-defined]
        if readings.ndim == 2:
            # Nothing perturbed: every trial stays at the calibration, as in the numpy iteration.
            np.testing.assert_allclose(direct[0], want, rtol=0.0, atol=1e-12 * np.abs(want).max())
        else:
            _assert_same_parameters(trials, direct[0], want)


@pytest.mark.parametrize(("layout", "six_dof"), [("paper_arm", False), ("paper_arm", True), ("ur10.urdf", True)])
@pytest.mark.parametrize("large", [False, True])
def test_errors_applied_in_the_kernel_equal_perturbed_values(layout: str, six_dof: bool, large: bool) -> None:
    """The measurement and reading errors handed to the kernel (``deviations``,
    ``reading_errors``), which applies them itself, give the trials of the numpy solver fed the
    perturbed values (the measurement type's ``perturb``) and readings:
    bit for bit where every angle error is small (the series on both sides), and to 1e-12
    where a trial holds a rotation error above 1e-3 rad (sin and cos of the angle)."""
    compiled, reference, trials = _solvers(layout, six_dof, "tracker")
    rng = np.random.default_rng(11)
    n = 29
    values = trials.points  # type: ignore[attr-defined]
    measurement = trials.problem.measurement  # type: ignore[attr-defined]
    q0 = trials.joint_positions  # type: ignore[attr-defined]
    dq = rng.uniform(-2e-5, 2e-5, (n, *q0.shape))
    q = q0[None] + dq
    errors = rng.normal(0.0, 1e-5, (n, values.shape[0], measurement.dimension))
    if six_dof:
        errors[..., 3:] = rng.normal(0.0, 1e-4, (n, values.shape[0], 3))
        if large:
            errors[3, 5, 3:] = (2e-3, -1e-3, 5e-4)  # one pose of one trial: sin and cos
    lambdas = np.full(n, trials.lambda_star)  # type: ignore[attr-defined]
    x_hat = trials.x_hat  # type: ignore[attr-defined]
    want, _ = reference.solve(q, measurement.perturb(values[None], errors), None, lambdas, x_hat)  # type: ignore[attr-defined]
    given = {"deviations": errors, "reading_errors": dq}
    got, _ = compiled.solve(q0, values[None], None, lambdas, x_hat, **given)  # type: ignore[attr-defined]
    numpy_path, _ = reference.solve(q0, values[None], None, lambdas, x_hat, **given)  # type: ignore[attr-defined]
    assert np.array_equal(numpy_path, want)  # the numpy solver perturbs as the caller did
    _assert_same_parameters(trials, got, want)
    perturbed = measurement.perturb(values[None], errors)
    kernel_values = np.array([_kernel_perturb(values, e, six_dof) for e in errors])
    if six_dof and large:
        assert np.abs(kernel_values - perturbed).max() <= 1e-15
    else:
        assert np.array_equal(kernel_values, perturbed)


def _kernel_perturb(values: np.ndarray, errors: np.ndarray, poses: bool) -> np.ndarray:
    from robocal_uncertainty.kernels._numba_walk import _perturb

    out = np.empty_like(values)
    _perturb(np.ascontiguousarray(values), np.ascontiguousarray(errors), poses, out)
    return out
