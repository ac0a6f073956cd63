"""``simulate --raw``: a raw recording (joint states and tracker points streamed while the arm
moves and dwells) that ``replay`` turns back into the simulated campaign, checked against the
simulation's own truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.bagio.raw_bag_simulator import read_raw_truth
from robocal_uncertainty.cli import main
from robocal_uncertainty.core import load_robot_model
from robocal_uncertainty.core.robot_formats.robot_yaml import resolve_robot_config
from robocal_uncertainty.pipeline.replay import replay_bag


def test_raw_recording_replays_to_the_simulated_poses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "raw.mcap"
    args = ["simulate", "--raw", "--poses", "20", "--dwell-s", "0.4", "--move-s", "0.4", "--seed", "3"]
    assert main([*args, "--out", str(out)]) == 0
    assert "wrote raw recording" in capsys.readouterr().out
    truth = json.loads(out.with_suffix(".truth.json").read_text(encoding="utf-8"))
    assert len(read_raw_truth(out).windows) == 20

    replayed = replay_bag(out, load_robot_model(resolve_robot_config("paper_arm")), calibrate=False, auto_window=True)
    assert replayed.campaign is not None and replayed.campaign.n_poses == 20
    # Each dwell's mean reading against the true joints: the encoders' +-0.005 deg noise
    # averaged over the dwell, so well inside the half-width.
    q_true = np.asarray(truth["true_joint_positions_rad"])
    q_replayed = np.asarray(replayed.campaign.joint_positions)
    assert np.max(np.abs(q_replayed - q_true)) < np.radians(0.005)
    # And the points against the true ones: the tracker's 5 µm (uniform) noise averaged likewise.
    p_true = np.asarray(truth["true_points_m"])
    assert np.max(np.abs(np.asarray(replayed.campaign.points) - p_true)) < 5e-6


def test_raw_recording_is_one_session(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["simulate", "--raw", "--sessions", "2", "--out", str(tmp_path / "r.mcap")])
    err = capsys.readouterr().err
    assert code != 0
    assert "--raw writes one recording" in err and "Traceback" not in err
    assert not (tmp_path / "r.mcap").exists()
