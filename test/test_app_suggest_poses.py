"""Next-best poses: the first-order ranking equals brute-force re-evaluation of the linearised
covariance, the top-ranked pose lowers the Monte Carlo uncertainty more than a bottom-ranked
one, and suggested poses beat random ones on simulated campaigns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app.pose_suggestion import (
    linearize,
    rank_candidates,
    suggest_poses,
    with_simulated_pose,
)
from robocal_uncertainty.core import RobotModel, SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.simulation import draw_joint_positions
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

REPO = Path(__file__).resolve().parents[1]
TEST_JOINTS = np.radians(
    [[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451], [30.0, -180.0, 45.0, 10.0, -20.0, 5.0]]
)
SETTINGS = UncertaintySettings()


@pytest.fixture(scope="module")
def arm() -> RobotModel:
    return load_robot_model(REPO / "robocal_uncertainty" / "data" / "paper_arm.yaml")


@pytest.fixture(scope="module")
def case(arm: RobotModel):
    campaign = simulate_campaign(arm, SimulationSettings(n_poses=20), seed=3).campaign
    calibration = identify(arm, campaign)
    lin = linearize(arm, campaign, TEST_JOINTS, calibration, SETTINGS)
    candidates = draw_joint_positions(arm, 200, rng=np.random.default_rng(1), margin=0.05)
    return campaign, calibration, lin, candidates


def test_first_order_ranking_equals_brute_force_reevaluation(arm: RobotModel, case) -> None:
    campaign, calibration, lin, candidates = case
    reductions = rank_candidates(arm, lin, candidates)
    before = float(np.sum(np.trace(lin.test_covariances(), axis1=1, axis2=2)))
    picks = [int(np.argmax(reductions)), int(np.argmin(reductions)), 7, 42, 99]
    brute = []
    for i in picks:
        # Re-linearise the campaign with the candidate added (at its predicted point) from scratch.
        bigger = with_simulated_pose(campaign, arm, calibration.estimate, candidates[i])
        relinearised = linearize(arm, bigger, TEST_JOINTS, calibration, SETTINGS)
        after = float(np.sum(np.trace(relinearised.test_covariances(), axis1=1, axis2=2)))
        brute.append(before - after)
    # The prior term uses the campaign's mean tracker variance, which one more pose barely moves.
    np.testing.assert_allclose(reductions[picks], brute, rtol=1e-3)
    assert np.all(reductions > 0)
    # Also against the plain information update of the same linearisation (exact Woodbury).
    from robocal_uncertainty.app.pose_suggestion import _pose_terms

    a_c, r_c = _pose_terms(arm, lin, candidates[picks])
    for j, i in enumerate(picks):
        updated = lin.information + a_c[j].T @ np.linalg.solve(r_c[j], a_c[j])
        after = float(np.sum(np.trace(lin.test_covariances(updated), axis1=1, axis2=2)))
        assert reductions[i] == pytest.approx(before - after, rel=1e-8)
    # The ranking order agrees with the brute force.
    assert np.argsort(brute).tolist() == np.argsort(reductions[picks]).tolist()


def test_top_ranked_pose_lowers_the_monte_carlo_uncertainty_more_than_a_bottom_ranked_one(
    arm: RobotModel, case
) -> None:
    campaign, calibration, lin, candidates = case
    reductions = rank_candidates(arm, lin, candidates)
    top, bottom = candidates[np.argmax(reductions)], candidates[np.argmin(reductions)]

    def u(c) -> float:
        result = evaluate_uncertainty(arm, c, TEST_JOINTS, uncertainty=SETTINGS, trials=2000, seed=5)
        return float(np.sqrt(np.mean([np.trace(p.covariance) for p in result.poses])))

    now = u(campaign)
    with_top = u(with_simulated_pose(campaign, arm, calibration.estimate, top))
    with_bottom = u(with_simulated_pose(campaign, arm, calibration.estimate, bottom))
    assert with_top < with_bottom
    assert now - with_top > 3 * (now - with_bottom)


def test_suggest_poses_reports_first_order_and_monte_carlo(arm: RobotModel, case) -> None:
    campaign, calibration, _, candidates = case
    result = suggest_poses(
        arm,
        campaign,
        TEST_JOINTS,
        calibration=calibration,
        candidates=candidates,
        count=4,
        monte_carlo_check=2,
        trials=1000,
        seed=2,
    )
    assert len(result.suggestions) == 4 and result.frame_id == "base_link"
    assert result.joint_names == arm.joint_names and result.trials == 1000
    first = result.suggestions[0]
    np.testing.assert_array_equal(first.joint_positions, candidates[np.argmax(result.reductions_m2)])
    predicted = [s.predicted_u_m for s in result.suggestions]
    assert result.current_u_m > predicted[0] > predicted[1] > predicted[2] > predicted[3]
    assert [s.monte_carlo_u_m is not None for s in result.suggestions] == [True, True, False, False]
    assert (
        result.monte_carlo_current_u_m > result.suggestions[0].monte_carlo_u_m > result.suggestions[1].monte_carlo_u_m
    )
    # First order and Monte Carlo agree to about 15 % here (the MC also re-selects lambda).
    assert result.current_u_m == pytest.approx(result.monte_carlo_current_u_m, rel=0.15)
    again = suggest_poses(arm, campaign, TEST_JOINTS, calibration=calibration, candidates=candidates, count=4)
    assert [s.predicted_u_m for s in again.suggestions] == predicted


def test_sampled_candidates_lie_inside_the_joint_limits(arm: RobotModel, case) -> None:
    campaign, calibration, _, _ = case
    result = suggest_poses(arm, campaign, TEST_JOINTS, calibration=calibration, n_candidates=50, count=2, seed=4)
    assert result.candidates.shape == (50, arm.n_joints)
    assert np.all(result.candidates >= arm.joint_limits[:, 0]) and np.all(result.candidates <= arm.joint_limits[:, 1])


def test_bad_inputs_raise_input_error(arm: RobotModel, case) -> None:
    campaign, calibration, _, _ = case
    with pytest.raises(InputError, match="outside its limits"):
        suggest_poses(arm, campaign, TEST_JOINTS, calibration=calibration, candidates=np.full((1, 6), 100.0))
    with pytest.raises(InputError, match="count"):
        suggest_poses(arm, campaign, TEST_JOINTS, calibration=calibration, count=0)
    with pytest.raises(InputError, match="test_joints"):
        suggest_poses(arm, campaign, np.zeros((2, 3)), calibration=calibration)
    with pytest.raises(InputError, match="no tracker or encoder noise"):
        suggest_poses(
            arm, campaign, TEST_JOINTS, calibration=calibration, settings=UncertaintySettings(sources=("lambda",))
        )


def test_suggested_poses_beat_random_poses(arm: RobotModel) -> None:
    """20 initial poses, then 5 suggested vs 5 random: Monte Carlo u_pos ratio over campaigns
    (benchmarks/bench_suggest_poses.py runs the issue's 10 + 10 over more campaigns)."""
    ratios = []
    for seed in range(2):
        campaign = simulate_campaign(arm, SimulationSettings(n_poses=20), seed=100 + seed).campaign
        calibration = identify(arm, campaign)
        suggested = suggest_poses(
            arm, campaign, TEST_JOINTS, calibration=calibration, n_candidates=300, count=5, seed=seed
        )
        chosen = np.array([s.joint_positions for s in suggested.suggestions])
        random = draw_joint_positions(arm, 5, rng=np.random.default_rng(seed + 50), margin=0.05)

        def u(c, seed: int = seed) -> float:
            result = evaluate_uncertainty(arm, c, TEST_JOINTS, uncertainty=SETTINGS, trials=1000, seed=seed)
            return float(np.sqrt(np.mean([np.trace(p.covariance) for p in result.poses])))

        ratios.append(
            u(with_simulated_pose(campaign, arm, calibration.estimate, chosen))
            / u(with_simulated_pose(campaign, arm, calibration.estimate, random))
        )
    assert max(ratios) < 1.0 and np.mean(ratios) < 0.97, ratios


def test_service_request_and_response_match_the_srv(arm: RobotModel, case) -> None:
    from rosbags.typesys import get_types_from_msg

    from robocal_uncertainty.app.pose_suggestion import service_arguments, service_response

    request_text, response_text = (REPO / "srv" / "SuggestPoses.srv").read_text(encoding="utf-8").split("\n---\n")
    (_, (_, request_fields)), *_ = get_types_from_msg(request_text, "robocal_uncertainty/srv/Req").items()
    (_, (_, response_fields)), *_ = get_types_from_msg(response_text, "robocal_uncertainty/srv/Res").items()
    defaults = service_arguments(
        n_joints=6, count=0, candidates=[], candidate_count=0, monte_carlo_check=0, trials=0, seed=3
    )
    assert defaults == {
        "candidates": None,
        "n_candidates": 500,
        "count": 5,
        "monte_carlo_check": 0,
        "trials": 2000,
        "seed": 3,
    }
    assert {"count", "candidates", "candidate_count", "monte_carlo_check", "trials", "seed"} == {
        name for name, _ in request_fields
    }
    campaign, calibration, _, candidates = case
    given = service_arguments(
        n_joints=6,
        count=2,
        candidates=candidates[:10].reshape(-1),
        candidate_count=0,
        monte_carlo_check=0,
        trials=0,
        seed=1,
    )
    np.testing.assert_array_equal(given["candidates"], candidates[:10])
    with pytest.raises(InputError, match="multiple of the 6 joints"):
        service_arguments(
            n_joints=6, count=1, candidates=[0.0] * 7, candidate_count=0, monte_carlo_check=0, trials=0, seed=0
        )
    result = suggest_poses(arm, campaign, TEST_JOINTS, calibration=calibration, **given)
    fields = service_response(result)
    assert set(fields) == {name for name, _ in response_fields}
    assert fields["success"] and len(fields["joint_positions"]) == 2 * 6 and len(fields["predicted_u"]) == 2
    assert np.isnan(fields["monte_carlo_current_u"]) and all(np.isnan(fields["monte_carlo_u"]))
    assert fields["frame_id"] == "base_link" and "2 pose(s) from 10 candidates" in fields["message"]
