"""The replay service: a raw bag -> static poses -> campaign -> :func:`~robocal_uncertainty.app.evaluate`.

:func:`~robocal_uncertainty.pipeline.replay.replay_bag` turns the bag into samples and a
campaign exactly as the nodes would; the evaluation is the same ``evaluate`` call the
command line's ``evaluate`` makes, so replaying a bag and evaluating the campaign it
recorded give the same numbers bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from robocal_uncertainty.app.evaluation import Evaluation, PhaseProgress, evaluate
from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import IdentifiabilityError
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.pipeline.collector import CollectorSettings, LogCallback
from robocal_uncertainty.pipeline.replay import ReplayResult, replay_bag
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = ["ReplayEvaluation", "replay"]


@dataclass(frozen=True, eq=False)
class ReplayEvaluation:
    """What :func:`replay` produced: the replay (samples, campaign, dropped messages) and its evaluation."""

    replay: ReplayResult
    evaluation: Evaluation


def replay(
    bag: str | Path,
    model: RobotModel,
    options: EvaluationSettings,
    *,
    joint_topic: str = JOINT_TOPIC,
    point_topic: str = POINT_TOPIC,
    tracker_pose_topic: str | None = None,
    tracker_frame_id: str | None = None,
    collector: CollectorSettings | None = None,
    campaign_path: str | Path | None = None,
    log: LogCallback | None = None,
    auto_window: bool = False,
    run: RunContext | None = None,
    phase_progress: PhaseProgress | None = None,
) -> ReplayEvaluation:
    """Replay a raw bag into a campaign and evaluate it with `options`.

    Parameters
    ----------
    bag : str or Path
        Raw recording: one MCAP file or a rosbag2 directory.
    model : RobotModel
        Nominal model.
    options : EvaluationSettings
        As for :func:`~robocal_uncertainty.app.evaluate`; must have ``test_joints``.
    joint_topic, point_topic, tracker_pose_topic, tracker_frame_id, collector, campaign_path, log, auto_window
        See :func:`~robocal_uncertainty.pipeline.replay.replay_bag`.
    run, phase_progress
        See :func:`~robocal_uncertainty.app.evaluate`.

    Raises
    ------
    BagError, CampaignError
        See :func:`~robocal_uncertainty.pipeline.replay.replay_bag`.
    IdentifiabilityError
        No static pose found (the message gives the likely cause), or too few to identify
        the model.
    """
    result = replay_bag(
        bag,
        model,
        joint_topic=joint_topic,
        point_topic=point_topic,
        tracker_pose_topic=tracker_pose_topic,
        tracker_frame_id=tracker_frame_id,
        collector=collector,
        options=options,
        campaign_path=campaign_path,
        calibrate=False,
        log=log,
        auto_window=auto_window,
    )
    if result.campaign is None:
        msg = f"{bag}: 0 static poses found: {result.diagnosis or 'nothing to calibrate'}"
        raise IdentifiabilityError(msg)
    evaluation = evaluate(
        model,
        result.campaign,
        options,
        run=run,
        phase_progress=phase_progress,
    )
    return ReplayEvaluation(replay=result, evaluation=evaluation)
