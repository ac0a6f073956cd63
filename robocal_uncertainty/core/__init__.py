"""ROS-free numerical core: robot model, kinematics, identification, campaigns, instruments, simulation.

Imports numpy, scipy and PyYAML only; a test forbids any ROS import here.
"""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.core.campaign import Campaign, PointFrame
    from robocal_uncertainty.core.identification import (
        IdentificationResult,
        fit_rigid_base,
        identify,
        residual_stats,
    )
    from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
    from robocal_uncertainty.core.joint_limits import check_joint_limits
    from robocal_uncertainty.core.kinematics import (
        forward_points,
        forward_points_and_jacobian,
        forward_poses,
        forward_poses_and_jacobian,
    )
    from robocal_uncertainty.core.observability import Observability, structural_observability
    from robocal_uncertainty.core.regularization import LCurve, lcurve
    from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, robot_model_from_dict
    from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel
    from robocal_uncertainty.core.rotation import (
        chordal_mean,
        euler_to_matrix,
        quaternion_from_matrix,
        quaternion_to_matrix,
        rotation_exp,
        rotation_log,
    )
    from robocal_uncertainty.core.sample import CalibrationSample
    from robocal_uncertainty.core.simulation import (
        ParameterErrorRanges,
        SimulatedCampaign,
        SimulationSettings,
        UnmodelledErrors,
        simulate_campaign,
        simulate_measurements,
    )

__all__ = [
    "CalibrationSample",
    "Campaign",
    "EncoderNoise",
    "IdentificationResult",
    "LCurve",
    "Observability",
    "ParameterErrorRanges",
    "ParameterLayout",
    "PointFrame",
    "RobotModel",
    "SimulatedCampaign",
    "SimulationSettings",
    "TrackerNoise",
    "UnmodelledErrors",
    "check_joint_limits",
    "chordal_mean",
    "euler_to_matrix",
    "fit_rigid_base",
    "forward_points",
    "forward_points_and_jacobian",
    "forward_poses",
    "forward_poses_and_jacobian",
    "identify",
    "lcurve",
    "load_robot_model",
    "quaternion_from_matrix",
    "quaternion_to_matrix",
    "residual_stats",
    "robot_model_from_dict",
    "rotation_exp",
    "rotation_log",
    "simulate_campaign",
    "simulate_measurements",
    "structural_observability",
]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
