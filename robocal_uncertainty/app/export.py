"""Export a calibration to where robots run: a corrected URDF, UR kinematics, or a robot YAML.

- ``urdf``: the input URDF (or, for a model given in DH form without one, a URDF generated
  from the model) with every movable joint's ``<origin>`` corrected so that its forward
  kinematics equal the calibrated model's; fixed joints, links and everything else unchanged;
  the calibration's identity in a comment at the top.
- ``ur-kinematics``: the ``kinematics:`` YAML that ``ur_description`` reads as
  ``kinematics_params_file`` (per joint ``x y z roll pitch yaw`` of the joint origin, and a
  ``hash``), for a Universal Robots chain (``shoulder_pan_joint`` ... ``wrist_3_joint``).
- ``yaml``: the package's own robot YAML (modified DH, SI units) of the calibrated model.

Beside every export, :attr:`Export.sidecar` states the uncertainty that travels with it: the
parameters with their standard uncertainties, which of them the data determined, their
covariance where the calibration file holds one, the tracker placement (not part of a URDF)
and the calibrated measured point in the tip link frame.

The writers live beside their readers in :mod:`robocal_uncertainty.core.robot_formats` (one
module per format); this module adds what every export shares: the calibration applied to the
nominal model, the identifying comment, the uncertainty sidecar.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.calibration_file import apply_calibration
from robocal_uncertainty.core.robot_formats import (
    EXPORT_FORMATS,
    ExportRequest,
    RobotSource,
    Written,
    robot_format_named,
)
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "SIDECAR_FORMAT",
    "Export",
    "calibrated_robot_description",
    "export_calibration",
]

Array = NDArray[np.float64]

SIDECAR_FORMAT = "robocal_uncertainty/export-uncertainty/1"


@dataclass(frozen=True)
class Export:
    """An exported calibration.

    Attributes
    ----------
    format : {"urdf", "ur-kinematics", "yaml"}
    text : str
        The file content.
    sidecar : dict
        The uncertainty that travels with it (JSON-ready; see the module docstring).
    point_in_tip : ndarray, shape (3,) [m]
        The calibrated measured point in the tip link frame (``urdf``, ``ur-kinematics``).
    tip_link : str
    """

    format: str
    text: str
    sidecar: dict[str, Any]
    point_in_tip: Array
    tip_link: str


def _identity(data: dict[str, Any]) -> dict[str, Any]:
    """What identifies a calibration: robot, date, campaign, residuals, sources."""
    keys = ("created", "date", "campaign", "sources", "session", "seed")
    out: dict[str, Any] = {
        "robot": data.get("robot"),
        "model_name": data.get("model_name"),
        "format": data.get("format"),
    }
    out.update({k: data[k] for k in keys if k in data})
    for k in ("n_poses", "residual_rms_before_m", "residual_rms_after_m", "residual_max_after_m", "lambda"):
        out[k] = data.get(k)
    return out


def _comment(data: dict[str, Any], where: str, what: str, uncertainty: str = "the sidecar JSON") -> str:
    ident = _identity(data)
    lines = [
        f"{what} written by robocal-uncertainty export from {where}.",
        f"robot {ident['robot']!r}, model {ident['model_name']!r}, {ident['n_poses']} poses",
    ]
    for key in ("created", "date", "campaign", "sources"):
        if key in ident:
            lines.append(f"{key}: {ident[key]}")
    session = ident.get("session")
    if isinstance(session, dict):  # format 2: the session record (its covariances are in the sidecar)
        lines.append(
            f"session: campaign {session.get('campaign')}, {session.get('n_poses')} poses in the "
            f"{session.get('frame')} frame {session.get('frame_id')}; scope: {data.get('scope', 'session')}"
        )
    rms_b, rms_a = ident.get("residual_rms_before_m"), ident.get("residual_rms_after_m")
    if isinstance(rms_b, (int, float)) and isinstance(rms_a, (int, float)):
        lines.append(f"residual RMS {1e3 * rms_b:.4g} mm before, {1e3 * rms_a:.4g} mm after calibration")
    lines.append(f"The parameters' uncertainty and which of them the data determine: see {uncertainty}.")
    return "\n".join(lines)


def _covariance_entry(data: dict[str, Any]) -> Any:
    return data.get("parameter_covariance") or data.get("covariance")


def _covariance(data: dict[str, Any], names: list[str]) -> tuple[list[list[float]] | None, str]:
    """The calibration's covariance over `names` if it holds one, else None and why.

    Format 2 calibration files hold it as ``parameter_covariance: {names, matrix}`` (the
    estimated parameters' linearised covariance); an older ``covariance`` key is read too."""
    cov = _covariance_entry(data)
    matrix, order = None, names
    if isinstance(cov, dict):
        matrix = cov.get("matrix")
        order = cov.get("parameters") or cov.get("names") or names
    elif isinstance(cov, list):
        matrix = cov
    if matrix is None:
        return None, (
            "the calibration file states standard uncertainties only (no covariance): correlations "
            "between parameters are not stated here; the Monte Carlo of `evaluate` gives the full statement"
        )
    try:
        arr = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros((0, 0))
    if arr.shape != (len(order), len(order)):
        return None, f"the calibration's covariance has shape {arr.shape}, not ({len(order)}, {len(order)}): left out"
    return (
        arr.tolist(),
        f"from the calibration file, over {len(order)} parameters (order: sidecar 'covariance_parameters')",
    )


def _sidecar(
    data: dict[str, Any], calibrated: RobotModel, point_in_tip: Array | None, tip: str | None
) -> dict[str, Any]:
    params = [p for p in data.get("parameters", []) if isinstance(p, dict)]
    names = [str(p.get("name")) for p in params]
    covariance, note = _covariance(data, names)
    cov = _covariance_entry(data)
    order = (cov.get("parameters") or cov.get("names")) if isinstance(cov, dict) else names
    return {
        "format": SIDECAR_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "calibration": _identity(data),
        "parameters": [
            {
                "name": p.get("name"),
                "unit": p.get("unit"),
                "nominal": p.get("nominal"),
                "estimate": p.get("estimate"),
                "determined_by_data": bool(p.get("estimated")),
                "standard_uncertainty": p.get("linearized_std"),
            }
            for p in params
        ],
        "not_identifiable": list(data.get("not_identifiable", [])),
        "covariance": covariance,
        "covariance_parameters": list(order or names) if covariance is not None else None,
        "covariance_note": note,
        "measurement_frame": {
            "note": (
                "world_T_base: the measurement (tracker) frame <- robot base; not part of a URDF "
                "(identity when the measurements were in the base frame)"
            ),
            "frame_id": calibrated.measurement_frame_id,
            "xyz": calibrated.base_xyz.tolist(),
            "rpy": calibrated.base_rpy.tolist(),
        },
        "measured_point_in_tip": None
        if point_in_tip is None
        else {"tip_link": tip, "xyz": [float(v) for v in point_in_tip]},
    }


def export_calibration(
    data: dict[str, Any],
    source: RobotSource,
    fmt: str,
    *,
    where: str = "calibration",
    urdf_text: str | None = None,
    uncertainty: str = "the sidecar JSON",
) -> Export:
    """Export a calibration (what :func:`read_calibration` returns) in format `fmt`.

    Parameters
    ----------
    data : dict
        The calibration file's content.
    source : RobotSource
        The nominal robot the calibration was identified on (and its URDF, where there is one).
    fmt : {"urdf", "ur-kinematics", "yaml"}
    where : str
        Names the calibration in messages and in the exported file's comment.
    urdf_text : str, optional
        The text of ``source.urdf`` when it is not a file (a ``robot_description`` parameter).
    uncertainty : str
        Where the comment says the uncertainty is stated.

    Raises
    ------
    ConfigError
        Unknown format, a calibration of another robot, a URDF that does not describe the
        model, a non-UR chain for ``ur-kinematics``.
    """
    if fmt not in EXPORT_FORMATS:
        msg = f"unknown export format {fmt!r}; known: {', '.join(EXPORT_FORMATS)}"
        raise ConfigError(msg)
    calibrated = apply_calibration(source.model, data, where=where)
    nominal = source.model.with_tool_rotation() if calibrated.tool_rotation else source.model
    request = ExportRequest(
        calibrated=calibrated,
        nominal=nominal,
        source=source.with_structure(),
        comment=lambda what: _comment(data, where, what, uncertainty),
        urdf_text=urdf_text,
    )
    written: Written = robot_format_named(fmt).load().write_calibrated(request)
    point = np.zeros(3) if written.point_in_tip is None else written.point_in_tip
    sidecar = _sidecar(data, calibrated, written.point_in_tip, written.tip_link)
    return Export(fmt, written.text, sidecar, point, written.tip_link or "")


def calibrated_robot_description(data: dict[str, Any], source: RobotSource, *, urdf_text: str | None = None) -> str:
    """The calibrated URDF as a string, for a ``robot_description`` topic.

    Parameters
    ----------
    data : dict
        A calibration (``calibration_to_dict``).
    source : RobotSource
        The nominal robot.
    urdf_text : str, optional
        The URDF text the model was read from (a ``robot_description`` parameter); without it
        the URDF file of `source`, or one generated from the model.
    """
    note = "the node's calibration_file"
    return export_calibration(
        data, source, "urdf", where="calibration_node", urdf_text=urdf_text, uncertainty=note
    ).text
