"""Machine-readable uncertainty report (JSON) with every unit stated.

Every number that carries a unit sits under a key ending in its unit: ``_m`` (metre),
``_m2`` (square metre), ``_rad`` (radian), ``_pct`` (percent). Keys without a suffix are
dimensionless (coverage factors, probabilities, counts) or, for the calibration
parameters, in the unit named by the entry's ``unit`` field (``m`` for lengths, ``rad``
for angles); ``lambda`` is in the column-scaled units of the identification. The
top-level ``units`` block repeats these rules. NaN and infinities are written as
``null``, so the file is strict JSON.

Arrays of numbers are written on one line each (objects stay indented): this keeps the
file readable and about 15 % smaller, which matters with hundreds of test
configurations (a 150-configuration report is under 1 MB). ``configuration_summary``
gives u_pos, the reach and the worst configuration at a glance.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any, cast

import numpy as np

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.rotation import quaternion_from_matrix
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.montecarlo import CoverageInterval, OutputSummary
from robocal_uncertainty.report.configurations import ConfigurationSummary, summarize_configurations
from robocal_uncertainty.uncertainty.calibration import (
    ROTATION_AXES,
    CalibrationUncertainty,
    PoseUncertainty,
)
from robocal_uncertainty.uncertainty.sources import SOURCE_DESCRIPTIONS
from robocal_uncertainty.uncertainty.sweeps import Sweep

__all__ = [
    "REPORT_FORMAT",
    "REPORT_FORMAT_VERSION",
    "UNITS",
    "calibration_to_dict",
    "merge_warnings",
    "read_report_json",
    "software_version",
    "to_json_value",
    "uncertainty_to_dict",
    "write_report_json",
]

REPORT_FORMAT = "robocal_uncertainty.uncertainty_report"
REPORT_FORMAT_VERSION = 1
AXES = ("x", "y", "z")

UNITS: dict[str, str] = {
    "_m": "metre",
    "_m2": "square metre (covariances of positions)",
    "_rad": "radian",
    "_rad2": "square radian (covariances of rotation deviations)",
    "_m_rad": "metre radian (position-rotation covariances)",
    "orientation": (
        "rotation deviations are rotation vectors about the fixed x, y, z axes of the output frame "
        "(R = exp([d]x) R_mean, the ROS PoseWithCovariance convention); quaternions are (x, y, z, w)"
    ),
    "_pct": "percent",
    "_m_per_m": "metre per metre of distance (tracker MPE slope)",
    "parameters": (
        "calibration parameter values are in the unit named by each entry's 'unit' field: "
        "'m' for lengths, 'rad' for angles"
    ),
    "lambda": "column-scaled units of the identification (dimensionless)",
    "no_suffix": "dimensionless (coverage factors, probabilities, counts, flags)",
}


def software_version() -> str:
    """Installed version of robocal_uncertainty, or ``"unknown"``."""
    try:
        return metadata.version("robocal_uncertainty")
    except metadata.PackageNotFoundError:
        return "unknown"


def to_json_value(value: object) -> Any:
    """Convert numpy scalars/arrays, tuples and non-finite floats to strict JSON values.

    Parameters
    ----------
    value : object
        Nested dicts, sequences, numpy arrays (any shape), numbers, str, bool or None.

    Returns
    -------
    object
        The same structure with lists, Python floats/ints and ``None`` for NaN/inf.
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.ndarray):
        return to_json_value(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): to_json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json_value(v) for v in value]
    msg = f"cannot write a {type(value).__name__} to the JSON report: {value!r}"
    raise InputError(msg)


def _interval(interval: CoverageInterval) -> dict[str, Any]:
    return {
        "kind": interval.kind,
        "coverage_probability": interval.coverage_probability,
        "low_m": interval.low,
        "high_m": interval.high,
    }


def _axis(name: str, axis: OutputSummary) -> dict[str, Any]:
    rel = axis.relative_expanded_uncertainty
    return {
        "axis": name,
        "estimate_m": axis.estimate,
        "standard_uncertainty_m": axis.standard_uncertainty,
        "expanded_uncertainty_m": axis.expanded_uncertainty,
        "expanded_from": axis.expanded_from,
        "coverage_factor": axis.coverage_factor,
        "relative_expanded_uncertainty_pct": None if rel is None else 100.0 * rel,
        "intervals": {
            "probabilistically_symmetric": _interval(axis.probabilistically_symmetric),
            "shortest": _interval(axis.shortest),
        },
    }


def _adequacy(result: CalibrationUncertainty) -> dict[str, Any]:
    ad = result.model_adequacy
    return {
        "test": "sum of squared residuals against the stated tracker and encoder noise propagated through "
        "the fit (Satterthwaite scaled chi-square)",
        "statistic": ad.chi2,
        "dof": ad.dof,
        "p_value": ad.p_value,
        "significance": ad.significance,
        "adequate": ad.adequate,
        "frame": "measurement",
        "residual_covariance_m2": ad.residual_covariance,
        "noise_covariance_m2": ad.noise_covariance,
        "model_error_covariance_m2": ad.inadequacy_covariance,
        "model_error_standard_uncertainty_m": ad.standard_uncertainty,
        # 6-DOF residuals: components x, y, z [m] then rx, ry, rz [rad] (the key's "_m" is the
        # position part's unit); every covariance above is in these units.
        "components": ["x", "y", "z", "rx", "ry", "rz"][: len(ad.standard_uncertainty)],
        "component_units": ["m", "m", "m", "rad", "rad", "rad"][: len(ad.standard_uncertainty)],
        "residual_dof": ad.residual_dof,
        "min_residual_dof": ad.min_residual_dof,
        "trustworthy": ad.trustworthy,
        "trust_note": ad.trust_note,
        "repeated_poses": getattr(ad, "repeated_poses", 0),
        # The model error the residual source drew: the field over the joint configurations
        # (None: adequate, residual off, or the independent model error).
        "model_error_field": None if result.model_error_field is None else result.model_error_field.to_dict(),
    }


def _rotation_axis(name: str, axis: OutputSummary, determined: bool) -> dict[str, Any]:
    """One rotation axis in radians; an undetermined axis carries no numbers."""
    if not determined:
        return {"axis": name, "determined": False}
    out = _axis(name, axis)
    out = {k[:-2] + "_rad" if k.endswith("_m") else k: v for k, v in out.items()}
    for interval in out["intervals"].values():
        interval["low_rad"] = interval.pop("low_m")
        interval["high_rad"] = interval.pop("high_m")
    out["determined"] = True
    return out


def _orientation(pose: PoseUncertainty) -> dict[str, Any] | None:
    o = pose.orientation
    if o is None:
        return None
    det = o.determined
    gum = o.gum
    return {
        "deviation_frame": "fixed x, y, z axes of the output frame (rotation vector of R_trial R_mean^T)",
        "mean_quaternion_xyzw": o.mean_quaternion,
        "mean_rotation_matrix": o.mean_rotation,
        "calibrated_quaternion_xyzw": quaternion_from_matrix(o.calibrated_rotation),
        "determined": list(det),
        "undetermined_directions": o.undetermined_directions,
        "undetermined_reason": (
            None
            if o.fully_determined
            else "the measurements cannot see a parameter change that rotates the tool about these axes "
            "(estimability test on the identification Jacobian); no uncertainty is stated about them"
        ),
        "standard_uncertainty_rad": [a.standard_uncertainty if d else None for a, d in zip(o.axes, det)],
        "expanded_uncertainty_rad": [a.expanded_uncertainty if d else None for a, d in zip(o.axes, det)],
        "covariance_rad2": o.covariance,
        "pose_covariance_m_rad": o.pose_covariance,
        "ros_pose_covariance": o.ros_covariance(pose.covariance),
        "axes": [_rotation_axis(n, a, d) for n, a, d in zip(ROTATION_AXES, o.axes, det)],
        "gum": {
            "applicable": gum.applicable,
            "about": "calibrated orientation",
            "standard_uncertainty_rad": gum.standard_uncertainty,
            "covariance_rad2": gum.covariance,
            "expanded_uncertainty_rad": gum.expanded_uncertainty,
            "coverage_factor": gum.coverage_factor,
            "validated": list(gum.validated),
        },
    }


def _pose(
    index: int, pose: PoseUncertainty, result: CalibrationUncertainty, summary: ConfigurationSummary
) -> dict[str, Any]:
    axes = pose.axes
    gum = pose.gum
    out: dict[str, Any] = {
        "index": index,
        "joint_positions_rad": pose.joint_positions,
        "frame": result.frame,
        "frame_id": result.frame_id,
        "mean_m": pose.mean,
        "standard_uncertainty_m": [a.standard_uncertainty for a in axes],
        "covariance_m2": pose.covariance,
        "expanded_uncertainty_m": [a.expanded_uncertainty for a in axes],
        "coverage_factor": [a.coverage_factor for a in axes],
        "coverage_probability": result.coverage_probability,
        "n_trials": result.n_trials,
        "converged": result.converged,
        "adaptive": result.adaptive is not None,
        "tolerance_reached_m": None,
        "numerical_tolerance_m": None,
        "converged_axes": None,
        "axes": [_axis(n, a) for n, a in zip(AXES, axes)],
        "gum": {
            "applicable": gum.applicable,
            "estimate_m": gum.estimate,
            "standard_uncertainty_m": gum.standard_uncertainty,
            "covariance_m2": gum.covariance,
            "expanded_uncertainty_m": gum.expanded_uncertainty,
            "coverage_factor": gum.coverage_factor,
            "validated": list(gum.validated),
            "d_low_m": gum.d_low,
            "d_high_m": gum.d_high,
            "delta_m": gum.delta,
        },
        "region": None,
        "orientation": _orientation(pose),
    }
    if result.adaptive is not None:
        cols = slice(3 * index, 3 * index + 3)
        out["tolerance_reached_m"] = list(result.adaptive.tolerance_reached[cols])
        out["numerical_tolerance_m"] = list(result.adaptive.delta[cols])
        # The run's verdict covers every output (parameters too); this is per axis here.
        out["converged_axes"] = [
            bool(t <= d) for t, d in zip(result.adaptive.tolerance_reached[cols], result.adaptive.delta[cols])
        ]
    if pose.region is not None:
        region = pose.region
        out["region"] = {
            "kind": "hyper-ellipsoid (JCGM 102)",
            "coverage_probability": region.coverage_probability,
            "coverage_factor": region.coverage_factor,
            "normal_coverage_factor": region.normal_coverage_factor,
            "semi_axes_m": summary.region_semi_axes[index],
            "mean_m": region.mean,
            "covariance_m2": region.covariance,
            "n_trials": region.n_trials,
        }
    return out


def _param_units(calibration: IdentificationResult) -> dict[str, str]:
    kinds = calibration.model.layout.kinds
    names = calibration.model.layout.names
    return {n: ("m" if k == "length" else "rad") for n, k in zip(names, kinds)}


def calibration_to_dict(calibration: IdentificationResult) -> dict[str, Any]:
    """Calibration summary of an :class:`IdentificationResult` as JSON-ready values."""
    units = _param_units(calibration)
    lc = calibration.lcurve
    held = calibration.held_by_regularisation
    return {
        "parameters": [
            {
                "name": name,
                "unit": units.get(name, "m"),
                "nominal": calibration.nominal[i],
                "estimate": calibration.estimate[i],
                "error": calibration.estimate[i] - calibration.nominal[i],
                "candidate": bool(calibration.candidates[i]),
                "estimated": bool(calibration.estimated[i]),
                "identifiable": bool(calibration.identifiable[i]),
                "linearized_std": calibration.linearized_std[i],
                "data_only_std": np.nan if calibration.data_only_std is None else calibration.data_only_std[i],
                "data_share": np.nan if calibration.data_share is None else calibration.data_share[i],
                "held_by_regularisation": bool(held[i]),
            }
            for i, name in enumerate(calibration.parameter_names)
        ],
        "dependencies": list(calibration.dependencies),
        "lambda": calibration.lambda_,
        "lambda_method": calibration.lambda_method,
        "lcurve_corner_lambda": lc.corner_lambda,
        "gcv_lambda": lc.gcv_lambda,
        "rms_before_m": calibration.rms_before,
        "max_before_m": calibration.max_before,
        "rms_after_m": calibration.rms_after,
        "max_after_m": calibration.max_after,
        "condition_number": calibration.condition_number,
        "iterations": calibration.iterations,
        "converged": calibration.converged,
        "status": calibration.status,
        "message": calibration.message,
        "base_initialised": calibration.base_initialised,
        "tool_initialised": calibration.tool_initialised,
        "n_poses": calibration.n_poses,
        "warnings": list(calibration.warnings),
        "measurement": _measurement(calibration),
    }


_WEIGHTING_TEXT = {
    "stated": "each residual component divided by the instrument's stated standard uncertainty (std, in its unit)",
    "variance_components": (
        "each residual component divided by its standard deviation estimated from the residual scatter "
        "(variance components, std, in its unit; never below the stated uncertainty, stated_std)"
    ),
}


def _measurement(calibration: IdentificationResult) -> dict[str, Any]:
    """What each pose measured and how its residual components were weighted."""
    m = calibration.measurement
    weights = m.weights
    out: dict[str, Any] = {
        "type": m.name,
        "components": list(m.component_names),
        "units": list(m.component_units),
        "weighting": "unweighted (every component weight 1 in its unit)"
        if weights is None
        else _WEIGHTING_TEXT.get(calibration.weighting, calibration.weighting),
        "weighting_method": calibration.weighting,
        "std": None if weights is None else (1.0 / weights).tolist(),
        # Point std is a tuple, pose std an array: both have a std where they have weights.
        "stated_std": None if weights is None else np.asarray(cast(Any, m).std, dtype=np.float64).tolist(),
        "variance_component_fits": calibration.weighting_iterations,
    }
    if m.measures_orientation:
        out["rotation_rms_before_rad"] = calibration.rotation_rms_before
        out["rotation_rms_after_rad"] = calibration.rotation_rms_after
    return out


def _settings(result: CalibrationUncertainty) -> dict[str, Any]:
    s = result.settings
    return {
        "sources": list(s.sources),
        "tracker_noise_a_m": s.tracker_noise.a,
        "tracker_noise_b_m_per_m": s.tracker_noise.b,
        "tracker_noise_kind": s.tracker_noise.kind,
        "tracker_xyz_m": list(s.tracker_xyz),
        "encoder_half_width_rad": s.encoder_noise.half_width,
        "linear_encoder_half_width_m": s.encoder_noise.linear_half_width,
        "lambda_range_setting": None if s.lambda_range is None else list(s.lambda_range),
        "lambda_range_used": None if result.lambda_range is None else list(result.lambda_range),
        "lambda_star": result.lambda_star,
        "min_poses": s.min_poses,
        "subset_size": s.subset_size,
        "gauss_newton_iterations": s.gauss_newton_iterations,
        "jacobian": s.jacobian,
        "model_error": s.model_error,
    }


def _budget(budget: Mapping[str, CalibrationUncertainty]) -> list[dict[str, Any]]:
    return [
        {
            "source": name,
            "sources": list(res.settings.sources),
            "n_trials": res.n_trials,
            "seed": res.seed,
            "standard_uncertainty_m": [[a.standard_uncertainty for a in pose.axes] for pose in res.poses],
        }
        for name, res in budget.items()
    ]


def _sweeps(sweeps: Sequence[Sweep]) -> list[dict[str, Any]]:
    return [
        {
            "name": sw.name,
            "xlabel": sw.xlabel,
            "values": sw.values,
            "standard_uncertainty_m": sw.standard_uncertainty,
            "reference": sw.reference,
            "n_trials": sw.n_trials,
            "seed": sw.seed,
        }
        for sw in sweeps
    ]


def _configuration_summary(summary: ConfigurationSummary) -> dict[str, Any]:
    return {
        "n_test_configurations": len(summary),
        "worst_index": summary.worst,
        "description": "u_pos = sqrt(u_x^2 + u_y^2 + u_z^2) per test configuration (in 'index' order); "
        "reach = distance of the tool from the robot base origin; worst_index = largest u_pos (0-based)",
        "position_uncertainty_m": summary.position_uncertainty,
        "reach_m": summary.reach,
        "gum_validated_all_axes": summary.gum_validated,
    }


_NUMBER = r"(?:-?\d[\d.eE+-]*|null|true|false)"
# indent= puts a newline after "[" and after every "," of an array; JSON strings never
# hold a raw newline, so this matches arrays of bare numbers only, never text.
_NUMBER_ARRAY = re.compile(r"\[\n\s*(" + _NUMBER + r"(?:,\n\s*" + _NUMBER + r")*)\n\s*\]")
_ITEM_BREAK = re.compile(r",\n\s*")


def _dumps(data: object) -> str:
    """Indented JSON with every array of bare numbers on one line (arrays of arrays stay split)."""
    text = json.dumps(data, indent=2, allow_nan=False, ensure_ascii=False)
    return _NUMBER_ARRAY.sub(lambda m: "[" + _ITEM_BREAK.sub(", ", m.group(1)) + "]", text)


def merge_warnings(*groups: Sequence[str]) -> list[str]:
    """One list of one-line warnings, in order, each message once.

    Raises
    ------
    InputError
        A group is a bare string (pass ``[text]``) or a warning is not a string.
    """
    out: list[str] = []
    for group in groups:
        if isinstance(group, str):
            msg = f"warnings must be a sequence of strings, got the string {group!r}"
            raise InputError(msg)
        for warning in group:
            if not isinstance(warning, str):
                msg = f"warnings must be strings, got {warning!r}"
                raise InputError(msg)
            if warning not in out:
                out.append(warning)
    return out


def _monte_carlo(result: CalibrationUncertainty) -> dict[str, Any]:
    """The Monte Carlo run's settings, backend and convergence."""
    return {
        "n_trials": result.n_trials,
        "seed": result.seed,
        "block_size": result.block_size,
        "backend": None
        if result.backend is None
        else {
            "name": result.backend.name,
            "version": result.backend.version,
            "requested": result.backend.requested,
        },
        "coverage_probability": result.coverage_probability,
        "converged": result.converged,
        "convergence_tested": result.adaptive is not None,
        "not_converged": list(getattr(result, "not_converged", ())),
        "adaptive": None
        if result.adaptive is None
        else {
            "converged": result.adaptive.converged,
            "n_dig": result.adaptive.n_dig,
            "n_sequences": result.adaptive.n_sequences,
            "sequence_trials": result.adaptive.sequence_trials,
            "max_trials": result.adaptive.max_trials,
            "interval": result.adaptive.interval,
        },
    }


def _parameters(result: CalibrationUncertainty) -> list[dict[str, Any]]:
    """Each identified parameter's estimate, uncertainty and coverage intervals, in its unit."""
    names = result.parameter_names
    units = _param_units(result.calibration)
    return [
        {
            "name": name,
            "unit": units.get(name, "m"),
            "estimate": ps.estimate,
            "standard_uncertainty": ps.standard_uncertainty,
            "expanded_uncertainty": ps.expanded_uncertainty,
            "coverage_factor": ps.coverage_factor,
            "probabilistically_symmetric": [
                ps.probabilistically_symmetric.low,
                ps.probabilistically_symmetric.high,
            ],
            "shortest": [ps.shortest.low, ps.shortest.high],
        }
        for name, ps in zip(names, result.parameters)
    ]


def uncertainty_to_dict(
    result: CalibrationUncertainty,
    *,
    robot_name: str,
    campaign_source: str | None = None,
    extra_settings: Mapping[str, object] | None = None,
    budget: Mapping[str, CalibrationUncertainty] | None = None,
    sweeps: Sequence[Sweep] | None = None,
    input_warnings: Sequence[str] = (),
) -> dict[str, Any]:
    """Strict-JSON dictionary of an uncertainty evaluation (format version 1).

    Parameters
    ----------
    result : CalibrationUncertainty
        Output of :func:`~robocal_uncertainty.uncertainty.evaluate_uncertainty`.
    robot_name : str
        Name of the robot model.
    campaign_source : str, optional
        Where the campaign came from (file path, "simulated seed=1", ...).
    extra_settings : mapping, optional
        Further JSON-serialisable settings to record verbatim (e.g. CLI options).
    budget : mapping of str to CalibrationUncertainty, optional
        Runs with one source each, for the uncertainty budget.
    sweeps : sequence of Sweep, optional
        Uncertainty sweeps (vs lambda, vs number of equations).
    input_warnings : sequence of str
        Warnings about the input data (e.g. the campaign reader's
        ``campaign.metadata["warnings"]``: a truncated file recovered); listed in
        ``warnings`` before the evaluation's own.

    Returns
    -------
    dict
        Only lists, dicts, str, finite floats, ints, bools and None.
    """
    summary = summarize_configurations(result)
    trust = result.model_adequacy.trust_note
    report: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "format_version": REPORT_FORMAT_VERSION,
        "software": {"name": "robocal_uncertainty", "version": software_version()},
        "units": UNITS,
        "robot_name": robot_name,
        "campaign_source": campaign_source,
        "monte_carlo": _monte_carlo(result),
        "output_frame": {
            "frame": result.frame,
            "frame_id": result.frame_id,
            "description": "frame of every position below: 'measurement' is the frame of the campaign's points, "
            "'base' the robot base frame",
        },
        "model_adequacy": _adequacy(result),
        "sources": [{"name": s, "description": SOURCE_DESCRIPTIONS.get(s, "")} for s in result.settings.sources],
        "settings": _settings(result),
        "extra_settings": dict(extra_settings) if extra_settings else {},
        "configuration_summary": _configuration_summary(summary),
        "test_configurations": [_pose(i, p, result, summary) for i, p in enumerate(result.poses)],
        "calibration": calibration_to_dict(result.calibration),
        "parameters": _parameters(result),
        "budget": None if budget is None else _budget(budget),
        "sweeps": None if sweeps is None else _sweeps(sweeps),
        "warnings": merge_warnings(input_warnings, result.warnings, [trust] if trust else []),
    }
    out: dict[str, Any] = to_json_value(report)
    return out


def write_report_json(
    path: str | Path,
    result: CalibrationUncertainty,
    *,
    robot_name: str,
    campaign_source: str | None = None,
    extra_settings: Mapping[str, object] | None = None,
    budget: Mapping[str, CalibrationUncertainty] | None = None,
    sweeps: Sequence[Sweep] | None = None,
    input_warnings: Sequence[str] = (),
) -> Path:
    """Write :func:`uncertainty_to_dict` to `path` (UTF-8, indented); return the path."""
    data = uncertainty_to_dict(
        result,
        robot_name=robot_name,
        campaign_source=campaign_source,
        extra_settings=extra_settings,
        budget=budget,
        sweeps=sweeps,
        input_warnings=input_warnings,
    )
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(_dumps(data) + "\n", encoding="utf-8")
    return out


def read_report_json(path: str | Path) -> dict[str, Any]:
    """Read a report written by :func:`write_report_json`, checking its format.

    Raises
    ------
    InputError
        Missing file, invalid JSON (NaN included), another format, or an unknown version.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as err:
        msg = f"cannot read uncertainty report {p}: {err}"
        raise InputError(msg) from err

    def _no_constants(name: str) -> None:
        msg = f"uncertainty report {p} contains {name}, which strict JSON forbids"
        raise InputError(msg)

    try:
        data = json.loads(text, parse_constant=_no_constants)
    except json.JSONDecodeError as err:
        msg = f"uncertainty report {p} is not valid JSON: {err}"
        raise InputError(msg) from err
    if not isinstance(data, dict) or data.get("format") != REPORT_FORMAT:
        msg = f"{p} is not a {REPORT_FORMAT} file (format = {data.get('format') if isinstance(data, dict) else None!r})"
        raise InputError(msg)
    version = data.get("format_version")
    if version != REPORT_FORMAT_VERSION:
        msg = (
            f"uncertainty report {p} has format_version {version!r}; this software "
            f"({software_version()}) reads version {REPORT_FORMAT_VERSION}"
        )
        raise InputError(msg)
    for key in ("test_configurations", "calibration", "monte_carlo", "units"):
        if key not in data:
            msg = f"uncertainty report {p} lacks the required key {key!r}"
            raise InputError(msg)
    return data
