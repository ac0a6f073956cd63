"""A URDF's unknown tool point (issue 20 follow-up): a UR10 campaign simulated with the shipped
DH model (probe 109 mm beyond the flange, points in the robot base frame) calibrated with the
shipped ``ur10.urdf`` (tip link ``tool0``, the flange: the probe is not in the URDF).

The tool point starts from a linear least-squares fit to the campaign and is not regularised,
so the calibration fits to the noise level (model adequacy p not ~0, no model error) and
predicts held-out points as the DH model does (the independent reference: same robot, tool
given in its YAML). A known probe (``tool_point`` given) keeps the old behaviour."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.identification import _initial_tool
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.measurement import POINT
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.core.urdf_model import load_urdf, robot_model_from_urdf, urdf_chain
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy

UR10_URDF = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data" / "ur10.urdf"
N_TRAIN, N_HELD = 40, 200
SETTINGS = SimulationSettings(n_poses=N_TRAIN + N_HELD, frame="base")


@pytest.fixture(scope="module")
def models():
    dh = load_robot_model(resolve_robot_config("ur10"))
    # `base`: the frame of the DH parameters (UR's controller base), a fixed child of base_link.
    urdf = robot_model_from_urdf(load_urdf(UR10_URDF), "base", "tool0")
    return dh, urdf


@pytest.mark.parametrize("seed", [1, 2, 5])
def test_urdf_calibration_fits_to_the_noise_and_predicts_as_the_dh_model(models, seed: int) -> None:
    dh, urdf = models
    assert not urdf.tool_known and urdf.tool_point[2] == pytest.approx(0.0922)  # the flange, not the probe
    sim = simulate_campaign(dh, SETTINGS, seed=seed)
    train, held = sim.campaign.subset(slice(0, N_TRAIN)), sim.campaign.subset(slice(N_TRAIN, None))
    cal_urdf = identify(urdf, train)
    cal_dh = identify(dh, train)
    assert cal_urdf.tool_initialised == "fit" and cal_dh.tool_initialised == "nominal"
    t0 = urdf.layout.tool_index
    assert not cal_urdf.penalized[t0 : t0 + 3].any() and cal_dh.penalized[dh.layout.tool_index]
    assert cal_urdf.estimate[t0 + 2] == pytest.approx(0.0922 + 0.109, abs=3e-3)  # probe found
    distances = np.linalg.norm(train.points - np.array(SETTINGS.tracker_xyz), axis=1)
    adequacy = {
        name: assess_model_adequacy(
            cal, train.joint_positions, SETTINGS.tracker_noise, SETTINGS.encoder_noise, distances
        )
        for name, cal in (("urdf", cal_urdf), ("dh", cal_dh))
    }
    # Before: 1.4-4.3 mm model error, p = 0 (tool held at the flange, and the points in UR's
    # `base` read as in `base_link`, which is now refused).
    assert adequacy["urdf"].adequate and adequacy["urdf"].p_value > 0.05, adequacy["urdf"].p_value
    assert np.all(adequacy["urdf"].inadequacy_covariance == 0.0)
    assert cal_urdf.rms_after < 1.05 * cal_dh.rms_after  # in-sample: at the noise level as the DH fit
    # The same URDF told the probe (--tool-point 0 0 0.109): the unknown tool point changes
    # neither the regularisation (the L-curve chose a lambda 10x smaller when the tool point
    # started at the flange, 109 mm from the probe) nor the predictions.
    known = robot_model_from_urdf(load_urdf(UR10_URDF), "base", "tool0", tool_point=(0.0, 0.0, 0.109))
    cal_known = identify(known, train)
    assert cal_urdf.lambda_ == pytest.approx(cal_known.lambda_, rel=0.3)
    # Held-out poses against the DH model's calibration (the independent reference: the probe
    # given in its YAML, and no mount.y/mount.pitch, which the URDF chain adds and these
    # simulated robots do not have).
    q = held.joint_positions
    pred = {
        name: forward_points(cal.model, cal.estimate, q)
        for name, cal in (("urdf", cal_urdf), ("dh", cal_dh), ("known", cal_known))
    }
    between = float(np.sqrt(np.mean(np.sum((pred["urdf"] - pred["dh"]) ** 2, axis=1))))
    rms = {name: float(np.sqrt(np.mean(np.sum((pred[name] - held.points) ** 2, axis=1)))) for name in pred}
    print(
        f"seed {seed}: lambda urdf {cal_urdf.lambda_:.3g} known-probe {cal_known.lambda_:.3g} dh {cal_dh.lambda_:.3g}; "
        f"p urdf {adequacy['urdf'].p_value:.3f} dh {adequacy['dh'].p_value:.3f}; held-out RMS urdf "
        f"{rms['urdf'] * 1e6:.1f} um known-probe {rms['known'] * 1e6:.1f} um dh {rms['dh'] * 1e6:.1f} um; "
        f"urdf - dh {between * 1e6:.1f} um"
    )
    assert np.allclose(pred["urdf"], pred["known"], rtol=0, atol=2e-6)
    assert rms["urdf"] < 1.15 * rms["dh"]
    assert between < 0.5 * rms["dh"]


def test_tool_fit_is_the_least_squares_tool_point(models) -> None:
    """Base frame: one linear solve; tracker frame: alternating with the rigid base fit, it finds
    the true tool point of a noise-free campaign of the nominal robot (exact: 1e-9 m)."""
    _, urdf = models
    truth = urdf.parameter_vector()
    t0 = urdf.layout.tool_index
    truth[t0 : t0 + 3] = (0.01, -0.02, 0.2)
    rng = np.random.default_rng(0)
    q = rng.uniform(-2.5, 2.5, size=(25, 6))
    points = forward_points(urdf, truth, q)
    start = urdf.parameter_vector()
    got = _initial_tool(urdf.layout, POINT, start, q, points, refit_base=False)
    assert got is not None and np.allclose(got[t0 : t0 + 3], truth[t0 : t0 + 3], rtol=0, atol=1e-12)
    b0 = urdf.layout.base_index
    truth[b0 : b0 + 6] = (2.0, 0.5, 0.3, 0.01, -0.02, 2.8)
    tracker_points = forward_points(urdf, truth, q)
    got = _initial_tool(urdf.layout, POINT, start, q, tracker_points, refit_base=True)
    assert got is not None and np.allclose(got[t0 : t0 + 3], truth[t0 : t0 + 3], rtol=0, atol=1e-9)
    assert np.allclose(got[b0 : b0 + 3], truth[b0 : b0 + 3], rtol=0, atol=1e-9)


def test_a_known_probe_is_regularised_from_its_value(models) -> None:
    """--tool-point X Y Z (here the probe the DH YAML states, in tool0) keeps the tool point
    regularised from the given value, as a robot YAML's tool_point is."""
    dh, _ = models
    known = robot_model_from_urdf(load_urdf(UR10_URDF), "base", "tool0", tool_point=(0.0, 0.0, 0.109))
    q = np.random.default_rng(5).uniform(-np.pi, np.pi, size=(50, 6))
    assert known.tool_known  # the same measured point as the DH model's
    np.testing.assert_allclose(
        forward_points(known, known.parameter_vector(), q), forward_points(dh, dh.parameter_vector(), q), atol=1e-12
    )
    sim = simulate_campaign(dh, dataclasses.replace(SETTINGS, n_poses=N_TRAIN), seed=3)
    cal = identify(known, sim.campaign)
    t0 = known.layout.tool_index
    assert cal.tool_initialised == "nominal" and cal.penalized[t0 + 2]


def test_a_base_link_fixed_beside_the_arm() -> None:
    """UR's `base` hangs off base_link by a fixed joint, beside the arm: the chain is expressed
    in it, and equals the DH model (whose base it is) to rounding."""
    robot = load_urdf(UR10_URDF)
    chain = urdf_chain(robot, "base")
    assert chain.tip_link == "wrist_3_link" and chain.joints[0].name == "base_link-base_link_inertia"
    model = robot_model_from_urdf(robot, "base", "wrist_3_link", tool_point=(0.0, 0.0, 0.0))
    dh = load_robot_model(resolve_robot_config("ur10"))
    p_dh = dh.parameter_vector()
    p_dh[dh.layout.tool_index : dh.layout.tool_index + 3] = 0.0
    q = np.random.default_rng(4).uniform(-np.pi, np.pi, size=(100, 6))
    np.testing.assert_allclose(
        forward_points(model, model.parameter_vector(), q), forward_points(dh, p_dh, q), rtol=0, atol=1e-12
    )
