"""A calibration result as JSON: what ``calibrate --json`` writes and ``fk --calibration`` reads."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError

__all__ = ["CALIBRATION_FORMAT", "apply_calibration", "calibration_to_dict", "read_calibration", "write_calibration"]

CALIBRATION_FORMAT = "robocal_uncertainty/calibration/1"


def _finite_or_none(values: NDArray[np.float64]) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=np.float64)]


def calibration_to_dict(result: IdentificationResult, *, robot: str) -> dict[str, Any]:
    """JSON-ready description of a calibration, SI units stated."""
    kinds = result.model.layout.kinds
    held = result.held_by_regularisation
    return {
        "format": CALIBRATION_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "robot": robot,
        "model_name": result.model.name,
        "joint_names": list(result.model.joint_names),
        "parameters": [
            {
                "name": name,
                "unit": "m" if kinds[i] == "length" else "rad",
                "nominal": float(result.nominal[i]),
                "estimate": float(result.estimate[i]),
                "estimated": bool(result.estimated[i]),
                "linearized_std": _finite_or_none(result.linearized_std[i : i + 1])[0],
                "held_by_regularisation": bool(held[i]),
                "data_only_std": (
                    None if result.data_only_std is None else _finite_or_none(result.data_only_std[i : i + 1])[0]
                ),
            }
            for i, name in enumerate(result.parameter_names)
        ],
        "not_identifiable": list(result.dependencies),
        "lambda": result.lambda_,
        "lambda_method": result.lambda_method,
        "condition_number": result.condition_number,
        "residual_rms_before_m": result.rms_before,
        "residual_max_before_m": result.max_before,
        "residual_rms_after_m": result.rms_after,
        "residual_max_after_m": result.max_after,
        "n_poses": result.n_poses,
        "iterations": result.iterations,
        "converged": result.converged,
        "message": result.message,
        "base_initialised": result.base_initialised,
        "warnings": list(result.warnings),
    }


def write_calibration(path: str | Path, result: IdentificationResult, *, robot: str) -> None:
    """Write :func:`calibration_to_dict` to `path`."""
    Path(path).write_text(json.dumps(calibration_to_dict(result, robot=robot), indent=2) + "\n", encoding="utf-8")


def read_calibration(path: str | Path) -> dict[str, Any]:
    """Read and check a calibration JSON file.

    Raises
    ------
    ConfigError
        Missing file, invalid JSON or not a calibration file.
    """
    file = Path(path)
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except OSError as err:
        msg = f"cannot read calibration {file}: {err.strerror}"
        raise ConfigError(msg) from err
    except UnicodeDecodeError as err:
        msg = f"calibration {file} is not UTF-8 JSON text (byte {err.start})"
        raise ConfigError(msg) from err
    except json.JSONDecodeError as err:
        msg = f"calibration {file} is not valid JSON: {err.msg} (line {err.lineno})"
        raise ConfigError(msg) from err
    if not isinstance(data, dict) or data.get("format") != CALIBRATION_FORMAT:
        msg = f"{file} is not a robocal_uncertainty calibration (format {CALIBRATION_FORMAT})"
        raise ConfigError(msg)
    return data


def _check_identity(model: RobotModel, data: dict[str, Any], where: str) -> None:
    """Refuse a calibration identified on another robot (model name, joint names)."""
    robot = data.get("model_name")
    if not isinstance(robot, str) or not robot:
        msg = f"{where} has no 'model_name': cannot tell whether it belongs to robot {model.name!r}"
        raise ConfigError(msg)
    if robot != model.name:
        msg = f"{where} was identified on robot {robot!r} and cannot be applied to robot {model.name!r}"
        raise ConfigError(msg)
    joints = data.get("joint_names")
    if joints is not None and (not isinstance(joints, list) or tuple(joints) != model.joint_names):
        msg = (
            f"{where} (robot {robot!r}) has joints {joints!r}, the robot {model.name!r} "
            f"has {list(model.joint_names)}: identified on another robot configuration"
        )
        raise ConfigError(msg)


def apply_calibration(model: RobotModel, data: dict[str, Any], *, where: str = "calibration") -> RobotModel:
    """Return `model` with the estimated parameters of a calibration file applied by name.

    The calibration must come from the same robot: its ``model_name`` must equal
    ``model.name``, its ``joint_names`` (when present; files before they were written lack
    them) ``model.joint_names``, and it must give exactly the model's parameters (plus
    ``tool.rx, tool.ry, tool.rz`` when it was identified from orientation data: the returned
    model then carries the tool rotation).

    Parameters
    ----------
    model : RobotModel
        The nominal model to apply the calibration to.
    data : dict
        What :func:`read_calibration` returns.
    where : str
        Names the calibration in messages, e.g. ``"calibration cal.json"``.

    Raises
    ------
    ConfigError
        The calibration belongs to another robot (model name, joint names or parameter
        names differ; the message names both robots) or has a non-finite estimate.
    """
    _check_identity(model, data, where)
    robot = data["model_name"]
    entries = data.get("parameters")
    if not isinstance(entries, list):
        msg = f"{where} has no 'parameters' list"
        raise ConfigError(msg)
    if any(isinstance(entry, dict) and entry.get("name") == "tool.rx" for entry in entries):
        # Calibrated with orientation data: the tool rotation is part of the calibration.
        model = model.with_tool_rotation()
    p = model.parameter_vector()
    names = model.layout.names
    seen: set[str] = set()
    for entry in entries:
        name = entry.get("name") if isinstance(entry, dict) else None
        if name not in names:
            msg = (
                f"{where}: parameter {name!r} (robot {robot!r}) does not exist in robot model "
                f"{model.name!r}: identified on another model layout"
            )
            raise ConfigError(msg)
        if name in seen:
            msg = f"{where}: parameter {name!r} is given twice"
            raise ConfigError(msg)
        seen.add(name)
        value = entry.get("estimate")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            msg = f"{where}: parameter {name!r} has no finite 'estimate', got {value!r}"
            raise ConfigError(msg)
        p[names.index(name)] = float(value)
    missing = [n for n in names if n not in seen]
    if missing:
        msg = (
            f"{where} (robot {robot!r}) lacks parameters {', '.join(missing)} of robot model "
            f"{model.name!r}: identified on another model layout"
        )
        raise ConfigError(msg)
    return model.with_parameters(p)
