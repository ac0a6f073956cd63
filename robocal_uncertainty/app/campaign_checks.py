"""Checks of a campaign against the robot it calibrates, for every front end alike.

A campaign read from a file can be wrong in ways no reader sees alone: joint readings outside
the robot's joint limits (often degrees read as radians), or a raw recording read as a
campaign (every streamed tracker point paired with a joint reading, so the motion between
poses becomes "poses" and the calibration is nonsense). The command line and the nodes both
call these, so a node refuses what the command line refuses, with the same one-line message.
"""

from __future__ import annotations

import numpy as np

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.joint_limits import check_joint_limits
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import InputError

__all__ = ["RAW_RECORDING_GAP_S", "check_campaign_joints", "refuse_raw_recording"]

RAW_RECORDING_GAP_S = 0.25
"""A campaign whose tracker points are typically closer in time than this [s] is a raw recording:
a robot cannot move to a new pose and settle that fast (the shipped raw bags stream points every
5 ms; a campaign has one point per pose, seconds apart)."""


def check_campaign_joints(model: RobotModel, campaign: Campaign, path: str) -> None:
    """Refuse campaign joint readings outside the robot's joint limits.

    Raises
    ------
    InputError
        A reading outside its joint's limits, naming `path`, the pose and the joint (with a
        hint when the readings look like degrees).
    """
    check_joint_limits(
        model,
        campaign.reorder_joints(model.joint_names).joint_positions,
        what=f"{path}: campaign pose",
        degrees_hint="the readings look like degrees (import-csv --angle-unit deg?)",
    )


def refuse_raw_recording(path: str, campaign: Campaign) -> None:
    """Refuse a raw recording read as a campaign (see the module docstring).

    Raises
    ------
    InputError
        The campaign's tracker points are typically less than :data:`RAW_RECORDING_GAP_S` apart.
    """
    stamps = campaign.stamps_ns
    if stamps is None or campaign.n_poses < 3:
        return
    gap_s = float(np.median(np.diff(np.sort(np.asarray(stamps, dtype=np.int64))))) / 1e9
    if gap_s < RAW_RECORDING_GAP_S:
        msg = (
            f"{path}: {campaign.n_poses} tracker points, typically {gap_s * 1e3:.3g} ms apart: this is a raw "
            "recording (a campaign has one point per static pose, seconds apart), not a campaign: use 'replay' on it"
        )
        raise InputError(msg)
