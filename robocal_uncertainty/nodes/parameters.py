"""Declaring node parameters: a descriptor for each (description with its unit, range,
read-only flag) and one on-set callback that refuses a bad value with the reason.

Each node lists its parameters as :class:`ParamSpec` and calls :func:`declare_parameters`.
The initial values (defaults, YAML, launch overrides) go through the same checks and a bad
one stops the node at start with a :class:`~robocal_uncertainty.errors.ConfigError`;
later ``ros2 param set`` calls get ``successful=False`` and the reason instead.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "BASE_UNKNOWN",
    "CAMPAIGN_PATH_READ",
    "DIAGNOSTICS_PERIOD",
    "READ_CAMPAIGN_AT_START",
    "ROBOT_CONFIG",
    "Check",
    "ParamSpec",
    "declare_parameters",
    "finite",
    "lambda_text",
    "non_empty",
    "one_of",
    "parse_lambda",
    "positive",
]

Check = Callable[[Any], "str | None"]
"""``check(value)`` returns the reason a value is refused, or None when it is accepted."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a node.

    Parameters
    ----------
    name : str
    default : bool, int, float, str, list or None
        Default value; its type is the parameter's type (never an empty list: ROS would
        take it for a byte array). None: not set unless given (with `dynamic_typing`).
    description : str
        What it is; the unit is appended as `` [unit]``.
    unit : str
        Unit of the value ("" for none).
    read_only : bool
        Fixed after start (structure the node was built from).
    low, high : int or float, optional
        Inclusive range, published in the descriptor and enforced by rclpy.
    check : callable, optional
        Further validation (see :data:`Check`).
    dynamic_typing : bool
        Accept other types too (e.g. an integer list for a float list); `check` must then
        validate the type.
    """

    name: str
    default: Any
    description: str
    unit: str = ""
    read_only: bool = False
    low: float | int | None = None
    high: float | int | None = None
    check: Check | None = None
    dynamic_typing: bool = False

    def descriptor(self) -> ParameterDescriptor:
        text = f"{self.description} [{self.unit}]" if self.unit else self.description
        descriptor = ParameterDescriptor(
            name=self.name, description=text, read_only=self.read_only, dynamic_typing=self.dynamic_typing
        )
        if self.low is not None and self.high is not None:
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                descriptor.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high), step=0)]
            elif isinstance(self.default, float):
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=float(self.low), to_value=float(self.high), step=0.0)
                ]
            descriptor.additional_constraints = f"{self.low} <= value <= {self.high}"
        return descriptor

    def validate(self, value: Any) -> str | None:
        """Reason `value` is refused (range and `check`), None when it is fine."""
        if (
            self.low is not None
            and self.high is not None
            and isinstance(value, (int, float))
            and not isinstance(value, bool)
            and not (self.low <= value <= self.high)
        ):
            return f"{value} is outside [{self.low}, {self.high}]" + (f" {self.unit}" if self.unit else "")
        if self.check is not None:
            return self.check(value)
        return None


def declare_parameters(
    node: Node,
    specs: Sequence[ParamSpec],
    *,
    on_change: Callable[[list[Parameter]], None] | None = None,
) -> dict[str, Any]:
    """Declare `specs` on `node`, check their initial values, install the on-set check.

    Parameters
    ----------
    node : Node
    specs : sequence of ParamSpec
    on_change : callable, optional
        Called with the accepted parameters after a successful run-time change has been
        validated (the new values are applied by rclpy right after the callback returns).

    Returns
    -------
    dict
        Initial value of every parameter.

    Raises
    ------
    ConfigError
        An initial value is refused (names the parameter and the reason).
    """
    by_name = {spec.name: spec for spec in specs}
    values: dict[str, Any] = {}
    for spec in specs:
        parameter = node.declare_parameter(spec.name, spec.default, spec.descriptor())
        values[spec.name] = parameter.value
    for name, value in values.items():
        reason = by_name[name].validate(value)
        if reason is not None:
            msg = f"parameter {node.get_name()}.{name}: {reason}"
            raise ConfigError(msg)

    def on_set(parameters: list[Parameter]) -> SetParametersResult:
        for parameter in parameters:
            spec = by_name.get(parameter.name)
            if spec is None:
                continue
            reason = spec.validate(parameter.value)
            if reason is not None:
                return SetParametersResult(successful=False, reason=f"{parameter.name}: {reason}")
        if on_change is not None:
            on_change(parameters)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return values


# -- checks --------------------------------------------------------------------------------


def finite(value: Any) -> str | None:
    """Refuse NaN and infinities."""
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be finite, got {value}"
    return None


def positive(value: Any) -> str | None:
    """Refuse values <= 0 (and NaN)."""
    if not (isinstance(value, (int, float)) and value > 0 and math.isfinite(value)):
        return f"must be > 0, got {value}"
    return None


def non_empty(value: Any) -> str | None:
    """Refuse an empty or blank string."""
    if not isinstance(value, str) or not value.strip():
        return "must not be empty"
    return None


def one_of(*choices: str) -> Check:
    """Accept exactly one of `choices`."""

    def check(value: Any) -> str | None:
        if value not in choices:
            return f"must be one of {', '.join(choices)}, got {value!r}"
        return None

    return check


def lambda_text(value: Any) -> str | None:
    """``auto``, ``lcurve``, ``gcv`` or a non-negative number written as text."""
    if value in ("auto", "lcurve", "gcv"):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return f"must be 'auto', 'gcv' or a number >= 0, got {value!r}"
    if not (math.isfinite(number) and number >= 0):
        return f"must be 'auto', 'gcv' or a number >= 0, got {value!r}"
    return None


def parse_lambda(value: str) -> str | float:
    """The ``lambda_`` argument of the identification for a checked :func:`lambda_text`."""
    return value if value in ("auto", "lcurve", "gcv") else float(value)


# Parameters every node shares: one definition, so descriptions and checks cannot drift.
ROBOT_CONFIG = ParamSpec(
    "robot_config",
    "paper_arm",
    "Robot model: a YAML file or a shipped model name (paper_arm, ur10)",
    read_only=True,
    check=non_empty,
)
BASE_UNKNOWN = ParamSpec(
    "base_unknown",
    False,
    "Identify the base transform even if the robot config says it is known",
    read_only=True,
)
CAMPAIGN_PATH_READ = ParamSpec(
    "campaign_path",
    "",
    "Campaign MCAP written by the collector, read at start (read-only); empty = $ROS_HOME/robocal/campaign.mcap",
    read_only=True,
)
READ_CAMPAIGN_AT_START = ParamSpec(
    "read_campaign_at_start", True, "Start from the samples already in the campaign file", read_only=True
)
DIAGNOSTICS_PERIOD = ParamSpec(
    "diagnostics_period_s", 1.0, "Period of the /diagnostics status", "s", True, 0.05, 3600.0
)
