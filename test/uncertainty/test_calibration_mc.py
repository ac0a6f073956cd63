"""Calibration Monte Carlo: reproducibility, agreement with independent solvers and the GUM,
and one-line errors for bad settings."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from robocal_uncertainty.core import (
    SimulationSettings,
    forward_points,
    identify,
    load_robot_model,
    simulate_campaign,
)
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty import (
    BatchProblem,
    ChordSolver,
    UncertaintySettings,
    evaluate_uncertainty,
    parse_sources,
)

ROOT = Path(__file__).resolve().parents[2]

TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])


@pytest.fixture(scope="module")
def paper():
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(), seed=11)
    return model, sim


def test_same_seed_same_result_whatever_chunk_and_workers(paper) -> None:
    model, sim = paper
    settings = UncertaintySettings(sources=("tracker", "encoder", "n_poses", "lambda"))
    runs = [
        evaluate_uncertainty(
            model,
            sim.campaign,
            TEST_JOINTS,
            uncertainty=settings,
            trials=1200,
            seed=5,
            block_size=500,
            run=RunContext(chunk_blocks=chunk, workers=workers),
        )
        for chunk, workers in ((1, 1), (3, 1), (2, 2))
    ]
    for other in runs[1:]:
        np.testing.assert_array_equal(runs[0].samples, other.samples)
    different = evaluate_uncertainty(
        model, sim.campaign, TEST_JOINTS, uncertainty=settings, trials=1200, seed=6, block_size=500
    )
    assert not np.array_equal(different.samples, runs[0].samples)


def test_chord_solver_matches_exact_gauss_newton(paper) -> None:
    model, sim = paper
    results = {
        jac: evaluate_uncertainty(
            model,
            sim.campaign,
            TEST_JOINTS,
            uncertainty=UncertaintySettings(sources=("tracker", "encoder", "pose_choice"), jacobian=jac),
            trials=400,
            seed=3,
        )
        for jac in ("frozen", "exact")
    }
    diff = np.abs(results["frozen"].samples[:, :3] - results["exact"].samples[:, :3]).max()
    u = np.sqrt(np.diag(results["exact"].poses[0].covariance))
    # The chord fixed point differs from Gauss-Newton's by (J_t - J*)^T r: second order,
    # here ~1e-8 m against u ~ 2e-5 m. Allow 1e-3 u.
    assert diff < 1e-3 * u.min()


def test_batched_reidentification_matches_scipy_least_squares(paper) -> None:
    """Independent reference: scipy's least_squares on each perturbed campaign (lambda = 0)."""
    model, sim = paper
    cal = identify(model, sim.campaign, lambda_=0.0)
    est = np.flatnonzero(cal.estimated)
    scale = cal.column_scale[est]
    problem = BatchProblem(model.layout, cal.nominal, est, scale)
    rng = np.random.default_rng(0)
    n_trials = 3
    q = sim.campaign.joint_positions[None] + rng.uniform(-1e-4, 1e-4, (n_trials, *sim.campaign.joint_positions.shape))
    pts = sim.campaign.points[None] + rng.uniform(-5e-6, 5e-6, (n_trials, sim.campaign.n_poses, 3))
    x_hat = (cal.estimate[est] - cal.nominal[est]) * scale
    solver = ChordSolver.at(problem, cal.estimate, sim.campaign.joint_positions)
    x, _ = solver.solve(q, pts, None, np.zeros(n_trials), x_hat)
    batch_params = problem.parameters(x)
    for t in range(n_trials):

        def resid(p_est, t=t):
            p = cal.nominal.copy()
            p[est] = p_est
            return (forward_points(model.layout, p, q[t]) - pts[t]).ravel()

        ref = least_squares(resid, cal.estimate[est], x_scale=1.0 / scale, xtol=1e-15, ftol=1e-15, gtol=1e-15)
        p_ref = cal.nominal.copy()
        p_ref[est] = ref.x
        y_ref = forward_points(model.layout, p_ref, TEST_JOINTS[None])
        y_batch = forward_points(model.layout, batch_params[t], TEST_JOINTS[None])
        assert np.abs(y_ref - y_batch).max() < 1e-8


def test_gum_agrees_with_monte_carlo_for_noise_sources(paper) -> None:
    model, sim = paper
    result = evaluate_uncertainty(
        model, sim.campaign, TEST_JOINTS, uncertainty=UncertaintySettings(), trials=20000, seed=2
    )
    pose = result.poses[0]
    u_mc = np.sqrt(np.diag(pose.covariance))
    assert pose.gum.applicable
    # The model is nearly linear at micrometre perturbations: first order should match the
    # Monte Carlo within its sampling error (~1/sqrt(2M) = 0.5 %) plus a margin: 3 %.
    np.testing.assert_allclose(pose.gum.standard_uncertainty, u_mc, rtol=0.03)
    # The mean moves by far less than u from the calibrated prediction.
    assert np.all(np.abs(pose.mean - pose.gum.estimate) < 0.05 * u_mc)


def test_nonsmooth_sources_mark_gum_not_applicable(paper) -> None:
    model, sim = paper
    result = evaluate_uncertainty(
        model, sim.campaign, TEST_JOINTS, uncertainty=UncertaintySettings(sources=("pose_choice",)), trials=300, seed=2
    )
    assert not result.poses[0].gum.applicable
    assert not any(result.poses[0].gum.validated)


def test_fewer_equations_give_larger_uncertainty(paper) -> None:
    model, sim = paper
    full = evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, trials=3000, seed=1)
    small = sim.campaign.subset(slice(0, 15))
    few = evaluate_uncertainty(model, small, TEST_JOINTS, trials=3000, seed=1)
    assert np.all(np.diag(few.poses[0].covariance) > np.diag(full.poses[0].covariance))


def test_positions_are_in_the_identified_base_frame_for_tracker_campaigns() -> None:
    """Tracker data cannot separate the base from joint 1's geometry: the base frame is the
    identified one (joint 1 nominal). The truth, seen from that frame, must be covered."""
    from robocal_uncertainty.core.robot_model import rpy_to_matrix

    model = dataclasses.replace(load_robot_model(ROOT / "config/paper_arm.yaml"), base_known=False)
    sim = simulate_campaign(model, SimulationSettings(frame="tracker"), seed=4)
    result = evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, trials=2000, seed=1, frame="base")
    assert result.frame_id == model.base_frame_id
    truth_world = forward_points(model.layout, sim.true_model.parameter_vector(), TEST_JOINTS[None])[0]
    b0 = model.layout.base_index
    base = result.calibration.estimate[b0 : b0 + 6]
    truth_base = rpy_to_matrix(base[3:]).T @ (truth_world - base[:3])
    u = np.sqrt(np.diag(result.poses[0].covariance))
    assert np.all(np.abs(result.poses[0].mean - truth_base) < 5 * u)
    # Seen from the true base frame instead, the unobservable joint-1 errors show up.
    p_true = sim.true_model.parameter_vector()
    p_true[b0:] = 0.0
    naive = forward_points(model.layout, p_true, TEST_JOINTS[None])[0]
    assert np.any(np.abs(result.poses[0].mean - naive) > 5 * u)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"trials": 0}, "trials must be a positive integer"),
        ({"trials": -5}, "trials must be a positive integer"),
        ({"trials": 10}, "trials: samples must have at least 11 trials for coverage 0.95"),
        ({"coverage": 1.0}, r"coverage probability must be in \(0, 1\)"),
        ({"coverage": 0.0}, r"coverage probability must be in \(0, 1\)"),
        ({"test_joint_positions": np.zeros(5)}, "test joints must have 6 values"),
        ({"test_joint_positions": np.zeros((0, 6))}, "at least one configuration"),
        (
            {"uncertainty": UncertaintySettings(sources=("lambda",), lambda_range=(10.0, 20.0))},
            "excludes the calibration's optimum",
        ),
        (
            {"uncertainty": UncertaintySettings(sources=("pose_choice",), subset_size=2)},
            "subset_size = 2 must lie between",
        ),
    ],
)
def test_bad_settings_give_one_line_errors(paper, kwargs, match) -> None:
    model, sim = paper
    call = {"test_joint_positions": TEST_JOINTS, "trials": 100, **kwargs}
    with pytest.raises(ConfigError, match=match) as info:
        evaluate_uncertainty(model, sim.campaign, call.pop("test_joint_positions"), **call)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tracker_xyz": (np.nan, 0.0, 0.0)}, "tracker_xyz must be 3 finite"),
        ({"tracker_xyz": (1.0, 2.0)}, "tracker_xyz must be 3 finite"),
        ({"tracker_xyz": ("a", 0.0, 0.0)}, "tracker_xyz must be 3 finite"),
        ({"gauss_newton_iterations": "3"}, "gauss_newton_iterations must be an integer"),
        ({"gauss_newton_iterations": 0}, "gauss_newton_iterations must be an integer"),
    ],
)
def test_bad_uncertainty_settings_give_one_line_errors(kwargs, match) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        UncertaintySettings(**kwargs)
    assert "\n" not in str(info.value)


def test_unknown_source_names_are_refused() -> None:
    with pytest.raises(ConfigError, match="unknown uncertainty source"):
        parse_sources("tracker,thermal")
    with pytest.raises(ConfigError, match="unknown uncertainty source"):
        UncertaintySettings(sources=("magic",))
    assert parse_sources("all") == (
        "tracker",
        "encoder",
        "lambda",
        "n_poses",
        "pose_choice",
        "residual",
        "tracker_orientation",
        "between_session",
    )


def test_residual_source_reflects_real_robot_scatter() -> None:
    """Residual scatter on the real UR10 dwarfs tracker noise; the residual source must show it."""
    from pathlib import Path

    from robocal_uncertainty.importers import read_tracker_csv

    csv = Path(ROOT / "test/data/ur10_laser_tracker/measurements_iso_cubes.csv")
    campaign = read_tracker_csv(csv)
    model = load_robot_model(ROOT / "config/ur10.yaml")
    perm = np.random.default_rng(0).permutation(campaign.n_poses)
    train = campaign.subset(perm[:53])
    # A configuration the calibration did not see: at its own poses the field's prediction error
    # is smaller (what the fit absorbed there is known), at a new one it is the model error's.
    test_q = campaign.joint_positions[perm[53]]
    settings_noise = UncertaintySettings(sources=("tracker", "encoder"))
    settings_resid = UncertaintySettings(sources=("residual",))
    noise = evaluate_uncertainty(model, train, test_q, uncertainty=settings_noise, trials=500, seed=0)
    resid = evaluate_uncertainty(model, train, test_q, uncertainty=settings_resid, trials=500, seed=0)
    u_noise = np.sqrt(np.trace(noise.poses[0].covariance))
    u_resid = np.sqrt(np.trace(resid.poses[0].covariance))
    rms_after = noise.calibration.rms_after
    # Model inadequacy: the prediction scatter is at least the residual RMS, and far above
    # what tracker and encoder noise alone explain.
    assert u_resid > 0.9 * rms_after
    assert u_resid > 3 * u_noise


def test_positions_default_to_the_measurement_frame_and_carry_the_base_uncertainty() -> None:
    """By default a tracker campaign's results are in the tracker frame, where the truth is
    directly comparable with measurements; the identified base adds its uncertainty."""
    model = dataclasses.replace(load_robot_model(ROOT / "config/paper_arm.yaml"), base_known=False)
    sim = simulate_campaign(model, SimulationSettings(frame="tracker"), seed=4)
    meas = evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, trials=2000, seed=1)
    base = evaluate_uncertainty(model, sim.campaign, TEST_JOINTS, trials=2000, seed=1, frame="base")
    assert meas.frame == "measurement" and meas.frame_id == sim.campaign.frame_id
    truth_world = forward_points(model.layout, sim.true_model.parameter_vector(), TEST_JOINTS[None])[0]
    u = np.sqrt(np.diag(meas.poses[0].covariance))
    assert np.all(np.abs(meas.poses[0].mean - truth_world) < 5 * u)
    # Same parameters, other frame: the base enters the measurement-frame result only, so its
    # generalised variance is larger there (rotation-invariant comparison).
    assert np.linalg.det(meas.poses[0].covariance) > np.linalg.det(base.poses[0].covariance)
    np.testing.assert_array_equal(meas.samples[:, 3:], base.samples[:, 3:])


@pytest.mark.parametrize("orientation", [False, True], ids=["points", "poses"])
@pytest.mark.parametrize("subsets", [False, True], ids=["all_poses", "subsets"])
def test_linear_start_converges_as_far_as_two_exact_steps(orientation: bool, subsets: bool) -> None:
    """The chord solver's first step from ``reference + J_q dQ`` (no kinematics) and one exact
    step leave each trial as close to the chord fixed point as two exact steps did.

    Reference: the fixed point itself, 12 exact steps from the exact start. Perturbations as in
    the Monte Carlo: tracker +-5 um, encoder +-0.005 deg, orientation 0.01 deg, lambda varied.
    """
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    rotation_std = float(np.radians(0.01))
    sim_settings = SimulationSettings(orientation_std=rotation_std) if orientation else SimulationSettings()
    campaign = simulate_campaign(model, sim_settings, seed=11).campaign
    cal = identify(model, campaign)
    measurement = cal.measurement
    problem = BatchProblem.from_calibration(cal)
    x_hat = problem.scaled_deviation(cal.estimate)
    solver = ChordSolver.at(problem, cal.estimate, campaign.joint_positions)
    rng = np.random.default_rng(4)
    n, n_poses = 48, campaign.n_poses
    q = campaign.joint_positions + rng.uniform(-1.0, 1.0, (n, *campaign.joint_positions.shape)) * np.radians(0.005)
    errors = np.zeros((n, n_poses, measurement.dimension))
    errors[..., :3] = rng.uniform(-5e-6, 5e-6, (n, n_poses, 3))
    if orientation:
        errors[..., 3:] = rng.normal(0.0, rotation_std, (n, n_poses, 3))
    measured = measurement.perturb(campaign.points[None], errors)
    weights = (rng.random((n, n_poses)) < 0.8).astype(np.float64) if subsets else None
    lambdas = cal.lambda_ * rng.uniform(0.5, 2.0, n)

    def solve(**options: object) -> tuple[np.ndarray, int]:
        return solver.solve(q, measured, weights, lambdas, x_hat, **options)  # type: ignore[arg-type]

    fixed_point, _ = solve(max_iterations=12, relative_tolerance=1e-15, linear_start=False)
    deviation = np.linalg.norm(fixed_point - x_hat, axis=1)
    assert np.all(deviation > 0)

    def error(x: np.ndarray) -> float:
        return float(np.max(np.linalg.norm(x - fixed_point, axis=1) / deviation))

    linear, steps = solve()
    exact, exact_steps = solve(linear_start=False)
    # The first-order prediction alone is already within ~2e-4 of the solution (an exact first
    # step: ~1.4e-4); a wrong J_q or sign would leave it at order 1.
    assert error(solve(max_iterations=1)[0]) < 1e-3
    # One exact step later both are at ~3e-8 (measured 2.9e-8 and 3.2e-8 on points).
    assert steps == exact_steps == 2
    assert error(linear) < 1e-7
    assert error(exact) < 1e-7


def test_chord_trials_stop_by_their_own_steps(paper) -> None:
    """A trial's result is the one it gets solved alone, however many steps the others take."""
    model, sim = paper
    cal = identify(model, sim.campaign)
    problem = BatchProblem.from_calibration(cal)
    x_hat = problem.scaled_deviation(cal.estimate)
    solver = ChordSolver.at(problem, cal.estimate, sim.campaign.joint_positions)
    rng = np.random.default_rng(8)
    n = 24
    q = sim.campaign.joint_positions + rng.uniform(-1e-4, 1e-4, (n, *sim.campaign.joint_positions.shape))
    pts = sim.campaign.points + rng.uniform(-5e-6, 5e-6, (n, *sim.campaign.points.shape))
    lambdas = np.full(n, cal.lambda_)

    # A tolerance between the trials' second-step ratios (~1e-4): some stop after 2 steps, some after 3.
    def alone(t: int, **options: object) -> tuple[np.ndarray, int]:
        return solver.solve(q[t : t + 1], pts[t : t + 1], None, lambdas[:1], x_hat, **options)  # type: ignore[arg-type]

    ratios = []
    for t in range(n):
        one, _ = alone(t, max_iterations=1)
        two, _ = alone(t, max_iterations=2, relative_tolerance=0.0)
        ratios.append(np.linalg.norm(two - one) / np.linalg.norm(one - x_hat))
    tolerance = float(np.median(ratios))
    batch, steps = solver.solve(q, pts, None, lambdas, x_hat, relative_tolerance=tolerance)
    solos = [alone(t, relative_tolerance=tolerance) for t in range(n)]
    assert steps == 3
    assert {s for _, s in solos} == {2, 3}
    solo = np.concatenate([x for x, _ in solos])
    scale = np.linalg.norm(solo - x_hat, axis=1)
    np.testing.assert_array_less(np.linalg.norm(batch - solo, axis=1), 1e-12 * scale)
