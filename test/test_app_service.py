"""One evaluation service: the command line, the replay of a shipped bag and the node logic
(sample store -> calibration pipeline -> app.evaluate) give bit-identical results for the same
campaign, options and seed, budget and sweeps included."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app import Evaluation, EvaluationSettings, evaluate, replay
from robocal_uncertainty.bagio import read_campaign
from robocal_uncertainty.bagio.messages import msg_to_sample, sample_to_msg
from robocal_uncertainty.cli import main
from robocal_uncertainty.core import load_robot_model
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.pipeline import CollectorSettings, SampleStore
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

REPO = Path(__file__).resolve().parents[1]
BASE_BAG = REPO / "test" / "data" / "paper_arm_base_raw.mcap"
COLLECTOR = CollectorSettings(window_s=0.1, guard_s=0.025, min_points=10)  # the test bags' short dwells
JOINTS_DEG = [[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451], [30.0, -180.0, 45.0, 10.0, -20.0, 5.0]]
OPTIONS = EvaluationSettings(
    uncertainty=UncertaintySettings(sources=("tracker", "encoder")),
    test_joints=np.radians(JOINTS_DEG),
    trials=300,
    seed=7,
    budget=True,
    budget_trials=100,
    sweeps=True,
    sweep_trials=30,
)


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a).tobytes()


def _assert_identical(a: Evaluation, b: Evaluation) -> None:
    assert _bits(a.calibration.estimate) == _bits(b.calibration.estimate)
    assert _bits(a.uncertainty.samples) == _bits(b.uncertainty.samples)
    assert list(a.budget) == list(b.budget) == ["tracker", "encoder"]
    for source in a.budget:
        assert _bits(a.budget[source].samples) == _bits(b.budget[source].samples)
    assert [s.name for s in a.sweeps] == [s.name for s in b.sweeps] == ["lambda", "equations"]
    for sa, sb in zip(a.sweeps, b.sweeps):
        assert _bits(sa.values) == _bits(sb.values)
        assert _bits(sa.standard_uncertainty) == _bits(sb.standard_uncertainty)
    assert a.warnings == b.warnings


@pytest.fixture(scope="module")
def replayed(tmp_path_factory: pytest.TempPathFactory):
    model = load_robot_model(resolve_robot_config("paper_arm"))
    campaign_path = tmp_path_factory.mktemp("service") / "campaign.mcap"
    return model, replay(BASE_BAG, model, OPTIONS, collector=COLLECTOR, campaign_path=campaign_path), campaign_path


def test_replay_equals_evaluate_of_the_recorded_campaign(replayed) -> None:
    model, result, campaign_path = replayed
    _assert_identical(result.evaluation, evaluate(model, read_campaign(campaign_path), OPTIONS))
    # The main run is the plain Monte Carlo call with these options.
    direct = evaluate_uncertainty(
        model,
        result.replay.campaign,
        OPTIONS.test_joints,
        uncertainty=OPTIONS.uncertainty,
        trials=OPTIONS.trials,
        seed=OPTIONS.seed,
    )
    assert _bits(direct.samples) == _bits(result.evaluation.uncertainty.samples)


def test_node_logic_equals_replay(replayed) -> None:
    """What the uncertainty node does: samples (through their message) into its store, the
    pipeline of the first n, then app.evaluate with the pipeline's calibration."""
    model, result, _ = replayed
    store = SampleStore(model)
    for sample in reversed(result.replay.samples):  # any arrival order
        assert store.add(msg_to_sample(sample_to_msg(sample)))
    pipeline = store.pipeline(len(store), options=OPTIONS)
    node = evaluate(model, pipeline.campaign, OPTIONS, calibration=pipeline.calibrate())
    _assert_identical(node, result.evaluation)


def test_command_line_equals_service(replayed, tmp_path: Path) -> None:
    _, result, campaign_path = replayed
    out = tmp_path / "report"
    joints = [str(v) for row in JOINTS_DEG for v in row]
    argv = ["evaluate", str(campaign_path), "--robot", "paper_arm", "--degrees", "--test-joints", *joints]
    argv += ["--sources", "tracker,encoder", "--trials", "300", "--seed", "7", "--budget-trials", "100"]
    argv += ["--sweep-trials", "30", "--no-progress", "--out", str(out)]
    argv += ["--backend", "numpy"]  # the service's (the library's default): compared bit for bit
    assert main(argv) == 0
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    text = json.dumps(report)
    ours = result.evaluation
    for pose in ours.uncertainty.poses:
        for value in pose.mean:
            assert repr(float(value)) in text
        for axis in pose.axes:
            assert repr(float(axis.standard_uncertainty)) in text
    for run in ours.budget.values():
        for axis in run.poses[0].axes:
            assert repr(float(axis.standard_uncertainty)) in text
    for sweep in ours.sweeps:
        for value in sweep.standard_uncertainty.reshape(-1):
            assert repr(float(value)) in text


def test_service_refuses_missing_test_joints_and_bad_trials(replayed) -> None:
    model, result, _ = replayed
    with pytest.raises(ConfigError, match="no test joint"):
        evaluate(model, result.replay.campaign, EvaluationSettings())
    with pytest.raises(ConfigError, match="budget_trials must be a positive integer"):
        EvaluationSettings(budget_trials=0)
    # The one entry the nodes and compensate share refuses what the command line refuses:
    # below 2/(1-p) trials (40 at 95 %, 20 at 90 %) no trial lies beyond the interval's ends.
    joints = np.zeros((1, model.n_joints))
    for trials, coverage, floor in ((11, 0.95, 40), (39, 0.95, 40), (19, 0.90, 20)):
        options = EvaluationSettings(test_joints=joints, trials=trials, coverage=coverage)
        with pytest.raises(ConfigError, match=rf"trials {trials} cannot state .* 2/\(1-p\) = {floor} trials"):
            evaluate(model, result.replay.campaign, options)
