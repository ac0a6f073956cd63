"""What identification, the Monte Carlo and export need from a kinematic chain.

Every format is read into one chain type, :class:`~robocal_uncertainty.core.robot_model.RobotModel`
(modified DH with Hayati's beta on near-parallel axes; a URDF chain is converted to it exactly,
its base link <- first axis held as the ``mount``), and every writer starts from it. The
protocol below names the part of it the rest of the package relies on beyond the forward
kinematics (which read the DH rows): a new chain type must give all of it, and a reader or
writer may rely on nothing else. mypy checks that :class:`RobotModel` satisfies it
(:func:`_robot_model_is_a_chain`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel

__all__ = ["KinematicChain"]


@runtime_checkable
class KinematicChain(Protocol):
    """A serial chain as identification, Monte Carlo and export see it.

    Attributes
    ----------
    name : str
    joint_names : tuple of str, length n_joints
        As in ``sensor_msgs/JointState``; campaigns are reordered to them.
    n_joints : int
    prismatic : tuple of bool, length n_joints
        Joints read in m (the others in rad).
    joint_limits : ndarray, shape (n_joints, 2) [rad or m]
    layout : ParameterLayout
        Names and places of the parameters in the flat vector the identification estimates.
    base_known, tool_known : bool
        Whether the base transform / the measured point are known (else fitted, not regularised).
    base_frame_id, measurement_frame_id : str
        TF names of the chain's base and of the measurement (tracker) frame.
    tool_point : ndarray, shape (3,) [m]
        The measured point in the last frame.
    """

    @property
    def name(self) -> str: ...

    @property
    def joint_names(self) -> tuple[str, ...]: ...

    @property
    def n_joints(self) -> int: ...

    @property
    def prismatic(self) -> tuple[bool, ...]: ...

    @property
    def joint_limits(self) -> NDArray[np.float64]: ...

    @property
    def layout(self) -> ParameterLayout: ...

    @property
    def base_known(self) -> bool: ...

    @property
    def tool_known(self) -> bool: ...

    @property
    def base_frame_id(self) -> str: ...

    @property
    def measurement_frame_id(self) -> str: ...

    @property
    def tool_point(self) -> NDArray[np.float64]: ...

    def parameter_vector(self) -> NDArray[np.float64]:
        """The flat parameter vector, shape (layout.size,) [m, rad]."""
        ...

    def with_parameters(self, params: NDArray[np.float64]) -> RobotModel:
        """A copy with its geometry from `params` (shape (layout.size,))."""
        ...

    def with_tool_rotation(self) -> RobotModel:
        """The chain with the tool rotation in its parameter vector (orientation measurements)."""
        ...

    def world_T_base(self) -> NDArray[np.float64]:
        """Measurement frame <- chain base, shape (4, 4) [m]."""
        ...


def _robot_model_is_a_chain(model: RobotModel) -> KinematicChain:
    """Never called: mypy --strict fails here if :class:`RobotModel` stops being a chain."""
    return model
