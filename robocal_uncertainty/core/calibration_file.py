"""A calibration result as JSON: what ``calibrate --json`` writes, ``fk --calibration`` and ``verify`` read.

Format ``robocal_uncertainty/calibration/3`` (SI units: m, rad; version 3 adds the
model-error field), a JSON object with

``format``, ``units``, ``robot``, ``model_name``, ``joint_names``
    What the file is and which robot it belongs to.
``parameters``
    One entry per parameter: ``name``, ``unit``, ``nominal``, ``estimate``, ``estimated``
    (whether the data determined it; the others keep their nominal value) and
    ``linearized_std``.
``not_identifiable``, ``lambda``, ``lambda_method``, ``condition_number``, residual statistics,
``n_poses``, ``iterations``, ``converged``, ``message``, ``base_initialised``, ``warnings``
    The identification (as in version 1).
``determined``
    Names of the estimated parameters (order of the covariance matrix).
``effective_parameters``
    Trace of the regularised fit's influence matrix.
``parameter_covariance``
    ``{"names": [...], "matrix": [[...]]}``: linearised covariance of the estimates from the
    stated noise plus the model error (products of m and rad); absent when the calibration
    carries no session record (orientation data).
``session``
    The session the calibration was measured in: ``frame`` (``tracker`` or ``base``),
    ``frame_id``, ``n_poses``, ``registration`` (``names`` base.x .. base.yaw, ``world_T_base``:
    the robot base pose in the measurement frame, and its ``covariance``), ``tool``
    (``point_m`` and its ``covariance``), ``campaign`` (the file it came from, when known),
    ``validated_level`` (the calibration's error level on its own held-out poses, what ``verify``
    tests a check against: ``level`` [m^2], ``dof``, ``kurtosis``, ``folds``, ``poses``, ``seed``,
    and since the repeated splits ``repeats`` and ``dispersion``; see
    :class:`~robocal_uncertainty.core.session.ValidatedLevel`).
``noise``
    The stated instruments: ``tracker_noise_a_m``, ``tracker_noise_b_m_per_m``,
    ``encoder_noise_half_width_rad``, ``linear_encoder_noise_half_width_m`` (prismatic joints;
    files without it read the default).
``model_error``
    ``covariance_base_m2``: per-pose covariance of what the kinematic model cannot represent,
    robot base frame; ``draws_base_m``: the residuals it is resampled from (whitened to it,
    base frame) and ``dof_estimate`` (its effective degrees of freedom); ``adequate``,
    ``chi2``, ``dof``, ``p_value`` of the adequacy test, ``included`` (whether the statement
    carries it) and ``cross_validated`` (when the model error came from held-out poses);
    ``field`` (version 3; ``null`` when the model error is independent from pose to pose): the
    model error correlated over the joint configurations
    (:mod:`robocal_uncertainty.core.model_error_field`): ``kernel``, ``metric``,
    ``correlated_fraction``, ``length_scale_rad``, ``dof`` (of its variance estimate),
    ``hyper_covariance`` (of log scale, correlated fraction, log length), the restricted
    ``log_likelihood`` and ``independent_log_likelihood``, ``joint_positions_rad`` (the
    calibration poses, model joint order), ``gain`` (``names``, ``matrix``: the estimates'
    change per base-frame point error at those poses, pose-major x y z) and ``residuals_m`` (the
    calibration's residuals at those poses, measurement frame, n x 3: what the field's
    correction, ``--field-correction``, conditions on) and ``cross_validation`` (the kriging
    variance's per-axis factors from the calibration's own folds, ``ratios`` and ``factors_xyz``,
    with ``folds``, ``bins``, ``seed``, ``n_poses`` and ``computed_from_sha256``, the digest of
    the poses, residuals, noise, field and gain they were computed from; see
    :mod:`robocal_uncertainty.core.field_cross_validation`); ``covariance_base_m2``
    is then the field's per-pose covariance.
``sources``
    Uncertainty sources of the statement.
``between_session``
    ``null`` for one session, or the between-session component estimated from several (see
    :mod:`robocal_uncertainty.uncertainty.sessions.between`): ``effects`` (``jointN.theta``
    [rad], ``length_scale`` [1]), their ``covariance`` for a future session, ``dof``, and a
    summary (group standard deviations, per-session effects).
``scope``
    ``"session"``: statements hold for the calibration session (its tracker set-up and
    probe mounting) only; ``"future sessions"``: a between-session component is included.
``settings``
    Free-form settings that produced the file (seed, weighting, ...).

Version 2 files (the same without ``model_error.field``) are read with an independent model
error. Version 1 files (``robocal_uncertainty/calibration/1``: the identification only) are
still read; :func:`read_session_state` returns None for them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.instruments import LINEAR_ENCODER_HALF_WIDTH, EncoderNoise, TrackerNoise
from robocal_uncertainty.core.model_error_field import FIELD_KERNEL, FIELD_METRIC, ModelErrorField
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.session import BASE_NAMES, TOOL_NAMES, SessionState, ValidatedLevel
from robocal_uncertainty.errors import ConfigError

__all__ = [
    "CALIBRATION_FORMAT",
    "CALIBRATION_FORMATS",
    "apply_calibration",
    "calibration_to_dict",
    "read_calibration",
    "read_session_state",
    "session_state_to_dict",
    "write_calibration",
]

CALIBRATION_FORMAT = "robocal_uncertainty/calibration/3"
"""The format written."""
_SESSION_FORMATS = ("robocal_uncertainty/calibration/2", CALIBRATION_FORMAT)
CALIBRATION_FORMATS: tuple[str, ...] = ("robocal_uncertainty/calibration/1", *_SESSION_FORMATS)
"""Formats read."""


def _finite_or_none(values: NDArray[np.float64]) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=np.float64)]


def _matrix(values: NDArray[np.float64]) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(values, dtype=np.float64)]


def session_state_to_dict(state: SessionState) -> dict[str, Any]:
    """The parts of a calibration file that :class:`SessionState` holds (see the module docstring)."""
    between = None
    if state.between_session_covariance is not None:
        between = dict(state.extra.get("between_session", {}))  # type: ignore[call-overload]
        between["effects"] = list(state.between_session_names)
        between["covariance"] = _matrix(state.between_session_covariance)
        between["dof"] = state.between_session_dof
    t0 = [state.covariance_names.index(n) for n in TOOL_NAMES if n in state.covariance_names]
    tool = state.extra.get("tool_point_m")
    return {
        "parameter_covariance": {
            "names": list(state.covariance_names),
            "matrix": _matrix(state.parameter_covariance),
        },
        "session": {
            "frame": state.frame,
            "frame_id": state.frame_id,
            "n_poses": state.n_poses,
            "registration": {
                "names": list(BASE_NAMES),
                "world_T_base": [float(v) for v in state.registration],
                "covariance": _matrix(state.registration_covariance),
            },
            "tool": {
                "names": list(TOOL_NAMES),
                "point_m": None if tool is None else list(tool),  # type: ignore[call-overload]
                "covariance": _matrix(state.covariance_of(TOOL_NAMES)) if t0 else None,
            },
            "campaign": state.extra.get("campaign"),
            "validated_level": None if state.validated_level is None else state.validated_level.to_dict(),
            "orientation_level": state.extra.get("orientation_level"),
        },
        "noise": {
            "tracker_noise_a_m": state.tracker_noise.a,
            "tracker_noise_b_m_per_m": state.tracker_noise.b,
            "encoder_noise_half_width_rad": state.encoder_noise.half_width,
            "linear_encoder_noise_half_width_m": state.encoder_noise.linear_half_width,
        },
        "model_error": {
            "covariance_base_m2": _matrix(state.model_error_covariance),
            "draws_base_m": None if state.model_error_draws is None else _matrix(state.model_error_draws),
            "dof_estimate": state.model_error_dof,
            "field": None if state.model_error_field is None else state.model_error_field.to_dict(),
            **dict(state.extra.get("model_adequacy", {})),  # type: ignore[call-overload]
        },
        "sources": list(state.sources),
        "between_session": between,
        "scope": state.scope,
        "settings": dict(state.extra.get("settings", {})),  # type: ignore[call-overload]
    }


def calibration_to_dict(
    result: IdentificationResult, *, robot: str, session: SessionState | None = None
) -> dict[str, Any]:
    """JSON-ready description of a calibration, SI units stated.

    Parameters
    ----------
    result : IdentificationResult
    robot : str
        The robot configuration it was identified with.
    session : SessionState, optional
        The session record (covariances, registration, noise, model error); without it the
        file says ``scope: session`` and carries no ``parameter_covariance``.
    """
    kinds = result.model.layout.kinds
    held = result.held_by_regularisation
    out = {
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
        "determined": [n for n, e in zip(result.parameter_names, result.estimated) if e],
        "effective_parameters": result.effective_parameters,
    }
    if session is not None:
        record = session_state_to_dict(session)
        out.update(record)
        field_record = record["model_error"]["field"]
        residuals = np.asarray(result.residuals, dtype=np.float64)
        if field_record is not None and residuals.shape == (session.n_poses, 3):
            # The field's correction (kriging) conditions on these; a URDF cannot carry them.
            field_record["residuals_m"] = _matrix(residuals)
            field_record["cross_validation"] = _field_cross_validation(result, out)
    else:
        out.update({"session": None, "scope": "session", "between_session": None})
    return out


def _field_cross_validation(result: IdentificationResult, data: dict[str, Any]) -> dict[str, Any] | None:
    """``model_error.field.cross_validation`` of `data` (its field and residuals written): the
    kriging variance's factors from the calibration's own folds, computed once here (seconds to
    a minute) so that every correction reads them back; None where the folds cannot be kriged
    (too few poses), and a correction computes or refuses then."""
    # The kriging modules read this module's files: imported here, not at its top.
    from robocal_uncertainty.core.field_cross_validation import factors_record
    from robocal_uncertainty.core.field_kriging import kriging_basis

    model = apply_calibration(result.model, data, where="the calibration")
    basis = kriging_basis(data, model, where="the calibration", cross_validate=False)
    try:
        return factors_record(basis, model.layout, model.parameter_vector())
    except (np.linalg.LinAlgError, ValueError):
        return None


def write_calibration(
    path: str | Path, result: IdentificationResult, *, robot: str, session: SessionState | None = None
) -> None:
    """Write :func:`calibration_to_dict` to `path`."""
    data = calibration_to_dict(result, robot=robot, session=session)
    Path(path).write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")


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
    if not isinstance(data, dict) or data.get("format") not in CALIBRATION_FORMATS:
        msg = f"{file} is not a robocal_uncertainty calibration (format {' or '.join(CALIBRATION_FORMATS)})"
        raise ConfigError(msg)
    return data


def _square(where: str, name: str, value: object, size: int) -> NDArray[np.float64]:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        msg = f"{where}: {name} is not a numeric matrix"
        raise ConfigError(msg) from err
    if array.shape != (size, size) or not np.isfinite(array).all():
        msg = f"{where}: {name} must be a finite {size}x{size} matrix, got shape {array.shape}"
        raise ConfigError(msg)
    return array


def read_session_state(data: dict[str, Any], *, where: str = "calibration") -> SessionState | None:
    """The session record of a calibration file, or None when it has none (version 1, orientation data).

    Raises
    ------
    ConfigError
        A session record that is incomplete or malformed (one line naming the field).
    """
    session = data.get("session")
    if data.get("format") not in _SESSION_FORMATS or session is None:
        return None
    try:
        cov = data["parameter_covariance"]
        names = tuple(str(n) for n in cov["names"])
        registration = session["registration"]
        noise = data["noise"]
        model_error = data["model_error"]
        tracker = TrackerNoise(a=float(noise["tracker_noise_a_m"]), b=float(noise["tracker_noise_b_m_per_m"]))
        encoder = EncoderNoise(
            half_width=float(noise["encoder_noise_half_width_rad"]),
            linear_half_width=float(noise.get("linear_encoder_noise_half_width_m", LINEAR_ENCODER_HALF_WIDTH)),
        )
        frame = session["frame"]
        reg = np.asarray(registration["world_T_base"], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as err:
        msg = f"{where}: incomplete session record ({err.__class__.__name__}: {err})"
        raise ConfigError(msg) from err
    if frame not in ("base", "tracker") or reg.shape != (6,) or not np.isfinite(reg).all():
        msg = f"{where}: session frame must be base or tracker with a 6-value registration"
        raise ConfigError(msg)
    extra: dict[str, object] = {
        "campaign": session.get("campaign"),
        "settings": data.get("settings") or {},
        "tool_point_m": (session.get("tool") or {}).get("point_m"),
        "orientation_level": session.get("orientation_level"),
        "model_adequacy": {
            k: v
            for k, v in model_error.items()
            if k not in ("covariance_base_m2", "draws_base_m", "dof_estimate", "field")
        },
    }
    between_names, between_cov, between_dof = _read_between(data.get("between_session"), where, extra)
    draws = _read_draws(model_error.get("draws_base_m"), where)
    me_field = _read_field(model_error.get("field"), where)
    level = _read_validated_level(session.get("validated_level"), where)
    return SessionState(
        frame=frame,
        frame_id=str(session.get("frame_id", "")),
        n_poses=int(session.get("n_poses", 0)),
        covariance_names=names,
        parameter_covariance=_square(where, "parameter_covariance.matrix", cov.get("matrix"), len(names)),
        model_error_covariance=_square(
            where, "model_error.covariance_base_m2", model_error.get("covariance_base_m2"), 3
        ),
        tracker_noise=tracker,
        encoder_noise=encoder,
        registration=reg,
        registration_covariance=_square(where, "session.registration.covariance", registration.get("covariance"), 6),
        sources=tuple(str(s) for s in data.get("sources") or ()),
        between_session_covariance=between_cov,
        between_session_names=between_names,
        between_session_dof=between_dof,
        model_error_draws=draws,
        model_error_dof=None if model_error.get("dof_estimate") is None else float(model_error["dof_estimate"]),
        scope=str(data.get("scope", "session")),
        extra=extra,
        model_error_field=me_field,
        validated_level=level,
    )


def _read_between(
    between: Any, where: str, extra: dict[str, object]
) -> tuple[tuple[str, ...], NDArray[np.float64] | None, float | None]:
    """Effect names, covariance and dof of a ``between_session`` record (its summary goes to `extra`)."""
    if between is None:
        return (), None, None
    try:
        between_names = tuple(str(n) for n in between["effects"])
        between_dof = None if between.get("dof") is None else float(between["dof"])
    except (KeyError, TypeError, ValueError) as err:
        msg = f"{where}: incomplete between_session record ({err.__class__.__name__}: {err})"
        raise ConfigError(msg) from err
    between_cov = _square(where, "between_session.covariance", between.get("covariance"), len(between_names))
    extra["between_session"] = {k: v for k, v in between.items() if k not in ("effects", "covariance", "dof")}
    return between_names, between_cov, between_dof


def _read_draws(draws: object, where: str) -> NDArray[np.float64] | None:
    """The model-error draws [m], n rows of 3, or None."""
    if draws is None:
        return None
    draws_array = np.asarray(draws, dtype=np.float64)
    if draws_array.ndim != 2 or draws_array.shape[1] != 3 or not np.isfinite(draws_array).all():
        msg = f"{where}: model_error.draws_base_m must be n rows of 3 finite values [m]"
        raise ConfigError(msg)
    return draws_array


def _read_validated_level(value: object, where: str) -> ValidatedLevel | None:
    """The ``session.validated_level`` record, or None."""
    if value is None:
        return None
    try:
        return ValidatedLevel.from_dict(dict(value))  # type: ignore[call-overload]
    except (KeyError, TypeError, ValueError) as err:
        msg = f"{where}: incomplete session.validated_level record ({err.__class__.__name__}: {err})"
        raise ConfigError(msg) from err


def _read_field(value: object, where: str) -> ModelErrorField | None:
    """``model_error.field`` of a version 3 file (None when absent or null)."""
    if value is None:
        return None
    try:
        assert isinstance(value, dict)
        if value.get("kernel") != FIELD_KERNEL or value.get("metric") != FIELD_METRIC:
            msg = (
                f"{where}: model_error.field has kernel {value.get('kernel')!r} and metric {value.get('metric')!r}; "
                f"this version reads {FIELD_KERNEL!r} over {FIELD_METRIC!r}"
            )
            raise ConfigError(msg)
        q = np.asarray(value["joint_positions_rad"], dtype=np.float64)
        gain = value["gain"]
        names = tuple(str(n) for n in gain["names"])
        matrix = np.asarray(gain["matrix"], dtype=np.float64)
        fraction = float(value["correlated_fraction"])
        length = float(value["length_scale_rad"])
        dof = float(value["dof"]) if value.get("dof") is not None else float("inf")
        hyper = _square(where, "model_error.field.hyper_covariance", value.get("hyper_covariance", np.zeros((3, 3))), 3)
    except (AssertionError, KeyError, TypeError, ValueError) as err:
        msg = f"{where}: incomplete model_error.field ({err.__class__.__name__}: {err})"
        raise ConfigError(msg) from err
    if (
        q.ndim != 2
        or matrix.shape != (len(names), 3 * q.shape[0])
        or not (np.isfinite(q).all() and np.isfinite(matrix).all())
        or not (0.0 <= fraction <= 1.0 and length > 0.0)
    ):
        msg = (
            f"{where}: model_error.field must hold n x n_joints joint positions, a k x 3n gain, "
            "a correlated fraction in [0, 1] and a positive length scale"
        )
        raise ConfigError(msg)
    return ModelErrorField(
        correlated_fraction=fraction,
        length_scale=length,
        joint_positions=q,
        gain_names=names,
        gain=matrix,
        dof=dof,
        log_likelihood=float(value.get("log_likelihood", float("nan")) or float("nan")),
        independent_log_likelihood=float(value.get("independent_log_likelihood", float("nan")) or float("nan")),
        hyper_covariance=hyper,
    )


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
