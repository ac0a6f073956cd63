"""Universal Robots' ``kinematics_params_file`` as an export format (written, not read): the
``kinematics:`` YAML that ``ur_description`` reads, per joint ``x y z roll pitch yaw`` of the
joint origin and a ``hash``, for a UR chain (``shoulder_pan_joint`` ... ``wrist_3_joint``)."""

from __future__ import annotations

import hashlib
from typing import Any

import yaml

from robocal_uncertainty.core.inverse_kinematics import UR_JOINT_NAMES
from robocal_uncertainty.core.robot_formats.source import ExportRequest, Written
from robocal_uncertainty.core.robot_formats.urdf import corrected_joint_origins
from robocal_uncertainty.errors import ConfigError

__all__ = ["UR_KINEMATICS_KEYS", "write_calibrated"]

UR_KINEMATICS_KEYS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def _clean(value: float) -> float:
    """``value`` as a float, with -0.0 written as 0.0."""
    return float(value) + 0.0


def write_calibrated(request: ExportRequest) -> Written:
    """The calibrated joint origins of a UR chain as a ``kinematics_params_file`` (the writer of
    this format); needs the robot's ``ur_description`` URDF."""
    if request.source.urdf is None:
        msg = (
            f"--format ur-kinematics needs the robot's ur_description URDF for model {request.source.model.name!r}: "
            "give --urdf (xacro ur.urdf.xacro ur_type:=... name:=ur > ur.urdf)"
        )
        raise ConfigError(msg)
    chain, origins, point = corrected_joint_origins(request)
    movable = chain.movable
    if len(movable) != 6 or not all(j.name.endswith(ur) for j, ur in zip(movable, UR_JOINT_NAMES)):
        msg = (
            f"--format ur-kinematics needs a Universal Robots chain ({', '.join(UR_JOINT_NAMES)}), "
            f"got {[j.name for j in movable]}"
        )
        raise ConfigError(msg)
    kin: dict[str, Any] = {}
    for key, joint in zip(UR_KINEMATICS_KEYS, movable):
        xyz, rpy = origins[joint.name]
        kin[key] = {
            "x": _clean(xyz[0]),
            "y": _clean(xyz[1]),
            "z": _clean(xyz[2]),
            "roll": _clean(rpy[0]),
            "pitch": _clean(rpy[1]),
            "yaw": _clean(rpy[2]),
        }
    digest = hashlib.sha256(repr(sorted((k, sorted(v.items())) for k, v in kin.items())).encode()).hexdigest()
    kin["hash"] = "calib_robocal_" + digest[:16]
    header = "".join(f"# {line}\n" for line in request.comment("UR kinematics_params_file").splitlines())
    return Written(header + yaml.safe_dump({"kinematics": kin}, sort_keys=False), point, chain.tip_link)
