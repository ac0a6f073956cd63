"""Calibration node: calibration samples -> identified model on ``robocal/calibration``.

Holds the samples of ``robocal/samples`` plus, at start, those already in the campaign
file (see :mod:`robocal_uncertainty.nodes.common`). Re-identifies the parameters once
``min_samples`` samples are there and then every ``recalibrate_every`` new samples, and on
request (``~/calibrate``, ``std_srvs/Trigger``). Each calibration is published as a
``robocal_uncertainty/CalibrationResult`` (reliable, transient local, depth 1: a late
subscriber gets the latest) and written to ``calibration_file`` (YAML, SI units stated;
default ``<campaign>.calibration.yaml`` next to the campaign), replacing it atomically. A
calibration requested through ``~/calibrate`` also writes its session record (the ``calibrate
--json`` file: parameter covariance, model error, registration, validated error level) to
``session_record_file`` (default ``<campaign>.session.json``): a later session's ``~/verify``
names it in ``verify_calibration``, no command line needed.
Its health (samples, condition number, residual RMS, lambda, convergence, time since the last
calibration; OK/WARN/ERROR) goes to ``/diagnostics`` every ``diagnostics_period_s``.
After each calibration the calibrated URDF goes to ``~/robot_description`` (``std_msgs/String``,
reliable, transient local, depth 1). The robot is read by the package's one robot loader
(:func:`robocal_uncertainty.core.robot_formats.load_robot_source`): ``robot_config`` names a
robot YAML, a shipped model or a URDF file (``.urdf``); a URDF in the ``robot_description``
parameter replaces ``robot_config``. For a URDF, file or parameter, ``base_link``/``tip_link``
give the chain (default the first serial chain) and ``tool_point_m`` the measured point.

Check measurement (``verify``, the shop-floor question "is my robot still within its
calibration today?"): with ``verify_calibration`` naming a calibration written by
``robocal-uncertainty calibrate --json`` in an earlier session, ``~/verify``
(``std_srvs/Trigger``) runs :func:`robocal_uncertainty.app.verification.verify`, the call of
``robocal-uncertainty verify``, on the samples held (the check campaign of this session,
5-20 poses): it re-registers the tracker (and the tool point with ``verify_retool``) and tests
the robot against its calibration. The answer is one line (consistent/drifted, p-value,
tracker move in mm and mrad; ``success`` false with the reason when the check is refused:
no or an unusable calibration file, too few or degenerate poses, a calibration without a
session record such as a 6-DOF one). The verdict goes to ``/diagnostics`` (OK consistent, WARN
drifted, ERROR refused), the full result as JSON (SI units, the ``verify --out`` report's
``verify.json`` plus ``summary`` and ``stamp_ns``) to ``robocal/verification``
(``std_msgs/String``, reliable, transient local, depth 1), and the report
(``verify.json``, ``verify.md``, ``verify.png``) to ``verify_report_dir`` (default
``<campaign>.verify/`` next to the campaign), replaced by each check. The check blocks this
node's callbacks while it runs (about a second with the default 20 000 null draws).
"""

from __future__ import annotations

from robocal_uncertainty._threads import limit_threads

# The command line's thread policy, so the node computes the command line's numbers; before
# numpy loads its BLAS.
limit_threads()

import json
import math
import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String
from std_srvs.srv import Trigger

from robocal_uncertainty.app.export import calibrated_robot_description
from robocal_uncertainty.app.verification import VerificationRun, calibrate_session, verify
from robocal_uncertainty.bagio.messages import calibration_to_msg, msg_to_sample
from robocal_uncertainty.core.calibration_file import calibration_to_dict, write_calibration
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.robot_formats import load_robot_source, robot_format_of, robot_source_from_description
from robocal_uncertainty.core.session import DEFAULT_NULL_TRIALS, DEFAULT_SIGNIFICANCE
from robocal_uncertainty.errors import CalibError, ConfigError, InputError
from robocal_uncertainty.msg import CalibrationResult as CalibrationResultMsg
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from robocal_uncertainty.nodes.common import (
    CauseLogger,
    campaign_file,
    diagnostic_array,
    run_node,
    to_ros,
)
from robocal_uncertainty.nodes.parameters import (
    BASE_UNKNOWN,
    CAMPAIGN_PATH_READ,
    DIAGNOSTICS_PERIOD,
    READ_CAMPAIGN_AT_START,
    ROBOT_CONFIG,
    ParamSpec,
    declare_parameters,
    lambda_text,
    parse_lambda,
)
from robocal_uncertainty.nodes.qos import DIAGNOSTICS_QOS, SAMPLE_QOS, latched_qos
from robocal_uncertainty.pipeline.diagnostics import (
    DiagnosticStatus,
    DiagnosticThresholds,
    calibration_status,
    verification_status,
)
from robocal_uncertainty.pipeline.sample_store import SampleStore
from robocal_uncertainty.report.verification_report import (
    verification_lines,
    verification_summary,
    verification_to_dict,
    write_verification_report,
)
from robocal_uncertainty.uncertainty.calibration.settings import EvaluationSettings

__all__ = ["PARAMETERS", "CalibrationNode", "main"]


def _tool_point(value: Any) -> str | None:
    if value is None:
        return None
    if (
        not isinstance(value, (list, tuple))
        or len(value) != 3
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    ):
        return f"must be 3 finite numbers (x, y, z in m), got {value!r}"
    return None


PARAMETERS: tuple[ParamSpec, ...] = (
    replace(
        ROBOT_CONFIG,
        description="Robot model: a YAML file, a shipped model name (paper_arm, ur10) or a URDF file (.urdf, its "
        "chain from base_link to tip_link)",
    ),
    BASE_UNKNOWN,
    CAMPAIGN_PATH_READ,
    READ_CAMPAIGN_AT_START,
    ParamSpec(
        "calibration_file",
        "",
        "YAML file the latest calibration is written to; empty = <campaign>.calibration.yaml next to the campaign",
        read_only=True,
    ),
    ParamSpec(
        "session_record_file",
        "",
        "JSON calibration with its session record (robocal-uncertainty calibrate --json format) written by each "
        "~/calibrate, for ~/verify of a later session (its verify_calibration); empty = <campaign>.session.json "
        "next to the campaign",
        read_only=True,
    ),
    ParamSpec(
        "lambda",
        "auto",
        "Regularisation: 'auto' (L-curve corner), 'gcv', or a fixed lambda in column-scaled units",
        "dimensionless",
        check=lambda_text,
    ),
    ParamSpec(
        "accept_unconverged",
        False,
        "Publish an identification that did not converge instead of logging the failure",
    ),
    ParamSpec(
        "min_samples", 10, "Fewest samples before the first automatic calibration", "samples", low=1, high=100_000
    ),
    ParamSpec(
        "recalibrate_every",
        1,
        "Re-identify automatically after this many new samples",
        "samples",
        low=1,
        high=100_000,
    ),
    DIAGNOSTICS_PERIOD,
    ParamSpec(
        "condition_warn",
        1e4,
        "Condition number of the scaled identification Jacobian above which /diagnostics warns",
        "dimensionless",
        True,
        1.0,
        1e300,
    ),
    ParamSpec(
        "residual_rms_warn_m",
        1e-4,
        "Residual RMS after calibration above which /diagnostics warns",
        "m",
        True,
        1e-12,
        1.0,
    ),
    ParamSpec(
        "verify_calibration",
        "",
        "Calibration JSON of an earlier session (written by robocal-uncertainty calibrate --json) that ~/verify "
        "checks the samples held against; empty = ~/verify refuses",
    ),
    ParamSpec(
        "tool_point_m",
        None,
        "With a URDF (robot_description or a .urdf robot_config): the measured point (probe, reflector) in "
        "tip_link, x y z, when known; unset = fitted to the campaign and not regularised",
        "m",
        read_only=True,
        check=_tool_point,
        dynamic_typing=True,
    ),
    ParamSpec("verify_retool", False, "~/verify re-registers the tool point too (the probe was remounted)"),
    ParamSpec(
        "verify_significance",
        DEFAULT_SIGNIFICANCE,
        "Level of ~/verify's test: its false-alarm rate when nothing changed",
        "",
        low=1e-6,
        high=0.5,
    ),
    ParamSpec(
        "verify_null_trials",
        DEFAULT_NULL_TRIALS,
        "Monte Carlo draws of ~/verify's test statistic when nothing changed",
        "draws",
        low=100,
        high=10_000_000,
    ),
    ParamSpec("verify_seed", 0, "Seed of those draws (same seed, same p-value)", low=0, high=2**62),
    ParamSpec(
        "verify_report_dir",
        "",
        "Directory ~/verify writes verify.json, verify.md and verify.png to (replaced by each check); "
        "empty = <campaign>.verify next to the campaign",
    ),
)


class CalibrationNode(Node):
    """The calibration as a ROS 2 node (see the module docstring)."""

    def __init__(self, *, node_name: str = "calibration_node", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._changed = False
        p = declare_parameters(self, PARAMETERS, on_change=self._note_change)
        self.robot_config = p["robot_config"]
        # A URDF in `robot_description` (as robot_state_publisher takes it) replaces robot_config.
        self._description = str(self.declare_parameter("robot_description", "").value)
        chain: dict[str, Any] = {k: str(self.declare_parameter(k, "").value) or None for k in ("base_link", "tip_link")}
        point = p["tool_point_m"]
        tool_point = None if point is None else [float(v) for v in point]
        base_known = False if p["base_unknown"] else None
        if self._description.strip():
            self._source = robot_source_from_description(
                self._description, **chain, tool_point=tool_point, base_known=base_known
            )
            self.robot_config = "robot_description"
        elif robot_format_of(self.robot_config).chain_ends:  # a URDF file: the same chain parameters
            self._source = load_robot_source(self.robot_config, **chain, tool_point=tool_point, base_known=base_known)
        elif tool_point is not None:
            msg = (
                "parameter tool_point_m describes the probe of a robot_description (URDF); "
                "a robot YAML gives tool_point"
            )
            raise ConfigError(msg)
        else:
            self._source = load_robot_source(self.robot_config, base_known=base_known)
        self.model = self._source.model
        self.store = SampleStore(self.model)
        self.campaign_path = campaign_file(p["campaign_path"])
        self.calibration_path = (
            Path(p["calibration_file"]).expanduser()
            if p["calibration_file"].strip()
            else self.campaign_path.with_name(self.campaign_path.stem + ".calibration.yaml")
        )
        self.session_record_path = (
            Path(p["session_record_file"]).expanduser()
            if p["session_record_file"].strip()
            else self.campaign_path.with_name(self.campaign_path.stem + ".session.json")
        )
        self._causes = CauseLogger(self, 5.0)
        self.calibrated_count = 0
        self.latest: IdentificationResult | None = None
        if p["read_campaign_at_start"] and self.campaign_path.exists():
            try:
                added, notes = self.store.load_campaign_file(self.campaign_path)
            except CalibError as err:
                self.get_logger().error(f"cannot read campaign {self.campaign_path}: {err}")
            else:
                for note in notes:
                    self.get_logger().warning(f"campaign {self.campaign_path}: {note}")
                self.get_logger().info(f"read {added} samples from {self.campaign_path}")
        self._result_pub = self.create_publisher(CalibrationResultMsg, "robocal/calibration", latched_qos())
        self._description_pub = self.create_publisher(String, "~/robot_description", latched_qos())
        self.create_subscription(CalibrationSampleMsg, "robocal/samples", self._on_sample, SAMPLE_QOS)
        self.create_service(Trigger, "~/calibrate", self._calibrate_service)
        self._verification_pub = self.create_publisher(String, "robocal/verification", latched_qos())
        self.create_service(Trigger, "~/verify", self._verify_service)
        self._check: dict[str, Any] = {}  # the last ~/verify: result or refusal
        self.create_timer(0.5, self._after_parameter_change)
        self._last_calibration_ns: int | None = None
        self._last_error: str | None = None
        self._thresholds = DiagnosticThresholds(
            condition_warn=p["condition_warn"], residual_rms_warn_m=p["residual_rms_warn_m"]
        )
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self.create_timer(p["diagnostics_period_s"], self._publish_diagnostics)
        self._maybe_calibrate()

    def _note_change(self, parameters: list[Parameter]) -> None:
        """A new lambda re-identifies the same samples (once rclpy has applied it)."""
        if any(parameter.name in ("lambda", "accept_unconverged") for parameter in parameters):
            self._changed = True

    def _after_parameter_change(self) -> None:
        if self._changed:
            self._changed = False
            if self.latest is not None:
                self._calibrate(min_samples=None)  # same samples, new lambda

    # -- input -----------------------------------------------------------------------------

    def _on_sample(self, msg: CalibrationSampleMsg) -> None:
        try:
            added = self.store.add(msg_to_sample(msg))
        except CalibError as err:
            self._causes.warning("bad_sample", f"sample dropped: {err}")
            return
        if added:
            self._maybe_calibrate()

    def _maybe_calibrate(self) -> None:
        n = len(self.store)
        min_samples = int(self.get_parameter("min_samples").value)
        every = int(self.get_parameter("recalibrate_every").value)
        if n >= min_samples and n - self.calibrated_count >= every:
            self._calibrate(min_samples=min_samples)

    def _calibrate_service(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        result = self._calibrate(min_samples=None)
        response.success = result is not None
        response.message = (
            f"calibrated from {result.n_poses} samples: residual RMS {result.rms_after * 1e3:.4f} mm"
            if result is not None
            else f"calibration failed with {len(self.store)} samples (see the log)"
        )
        return response

    # -- calibration -----------------------------------------------------------------------

    def _calibrate(self, *, min_samples: int | None) -> IdentificationResult | None:
        """Identify from every sample held; publish and write the result."""
        n = len(self.store)
        if n == 0:
            self.get_logger().warning("no samples to calibrate from")
            return None
        lambda_ = parse_lambda(str(self.get_parameter("lambda").value))
        try:
            options = EvaluationSettings(
                lambda_=lambda_, accept_unconverged=bool(self.get_parameter("accept_unconverged").value)
            )
            result = self.store.pipeline(options=options, min_samples=min_samples).calibrate()
        except CalibError as err:
            self.calibrated_count = n  # retry after the next `recalibrate_every` samples
            self._last_error = str(err)
            self._causes.warning("calibration_failed", f"calibration from {n} samples failed: {err}")
            return None
        self.calibrated_count = n
        self.latest = result
        self._last_error = None
        stamp = self.get_clock().now().nanoseconds
        self._last_calibration_ns = stamp
        self._result_pub.publish(to_ros(calibration_to_msg(result, stamp_ns=stamp), CalibrationResultMsg))
        self.get_logger().info(
            f"calibrated from {n} samples: residual RMS {result.rms_before * 1e3:.4f} -> "
            f"{result.rms_after * 1e3:.4f} mm, lambda {result.lambda_:.4g} ({result.lambda_method})"
        )
        self._publish_description(result)
        try:
            self._write(result)
        except OSError as err:
            self.get_logger().error(f"cannot write {self.calibration_path}: {err}")
        if min_samples is None:
            # On request only: the record re-identifies and validates on five folds (seconds),
            # too slow for the automatic calibration after every sample.
            self._write_session_record(lambda_)
        return result

    def _write_session_record(self, lambda_: str | float) -> None:
        """The calibration with its session record (``calibrate --json``), for ~/verify of a later session."""
        campaign = self.store.pipeline().campaign
        if campaign is None:
            return
        try:
            record = calibrate_session(
                self.model,
                campaign,
                tracker_noise=TrackerNoise(),
                encoder_noise=EncoderNoise(),
                lambda_=lambda_,
                accept_unconverged=bool(self.get_parameter("accept_unconverged").value),
                campaign_name=str(self.campaign_path),
            )
            if record.state is None:
                raise ConfigError("; ".join(record.warnings))
            self.session_record_path.parent.mkdir(parents=True, exist_ok=True)
            temporary = self.session_record_path.with_name(self.session_record_path.name + ".tmp")
            write_calibration(temporary, record.result, robot=self.robot_config, session=record.state)
            os.replace(temporary, self.session_record_path)
        except (CalibError, OSError) as err:
            self.get_logger().error(f"no session record written to {self.session_record_path}: {err}")
            return
        self.get_logger().info(
            f"session record written to {self.session_record_path}: a later session's ~/verify checks against it "
            "(its parameter verify_calibration)"
        )

    def diagnostic_status(self) -> DiagnosticStatus:
        """The calibration's health (rules in :mod:`robocal_uncertainty.pipeline.diagnostics`)."""
        latest = self.latest
        return calibration_status(
            name=f"{self.get_name()}: identification",
            hardware_id=self.model.name,
            now_ns=self.get_clock().now().nanoseconds,
            samples=len(self.store),
            min_samples=int(self.get_parameter("min_samples").value),
            last_calibration_ns=self._last_calibration_ns,
            condition_number=None if latest is None else float(latest.condition_number),
            residual_rms_m=None if latest is None else float(latest.rms_after),
            lambda_=None if latest is None else float(latest.lambda_),
            converged=None if latest is None else bool(latest.converged),
            error=self._last_error,
            thresholds=self._thresholds,
        )

    def verification_diagnostic_status(self) -> DiagnosticStatus:
        """The last check's verdict (rules in :mod:`robocal_uncertainty.pipeline.diagnostics`)."""
        check = self._check
        run: VerificationRun | None = check.get("run")
        result = None if run is None else run.verification
        move = None if result is None else result.move
        return verification_status(
            name=f"{self.get_name()}: verify",
            hardware_id=self.model.name,
            now_ns=self.get_clock().now().nanoseconds,
            calibration=str(self.get_parameter("verify_calibration").value),
            last_check_ns=check.get("stamp_ns"),
            consistent=None if result is None else bool(result.consistent),
            summary=str(check.get("summary", "")),
            error=check.get("error"),
            p_value=None if result is None else float(result.p_value),
            n_poses=None if result is None else int(result.n_poses),
            tracker_move_m=None if move is None else float(move.distance),
            tracker_turn_rad=None if move is None else float(move.angle),
        )

    def _publish_diagnostics(self) -> None:
        statuses = [self.diagnostic_status()]
        if self._check or str(self.get_parameter("verify_calibration").value).strip():
            statuses.append(self.verification_diagnostic_status())
        self._diagnostics_pub.publish(diagnostic_array(self, statuses))

    # -- check measurement -------------------------------------------------------------------

    @property
    def verify_report_dir(self) -> Path:
        """Where ``~/verify`` writes its report."""
        given = str(self.get_parameter("verify_report_dir").value).strip()
        if given:
            return Path(given).expanduser()
        return self.campaign_path.with_name(self.campaign_path.stem + ".verify")

    def _verify_service(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self.verify_samples()
        return response

    def verify_samples(self) -> tuple[bool, str]:
        """Check the samples held against ``verify_calibration``: (ran, one-line answer).

        A refusal (no or an unusable calibration, a check that cannot re-register) is
        ``(False, "refused: <reason>")``, logged, and ERROR on ``/diagnostics``; it never
        stops the node.
        """

        def get(name: str) -> Any:
            return self.get_parameter(name).value

        stamp = self.get_clock().now().nanoseconds
        path = str(get("verify_calibration")).strip()
        try:
            if not path:
                msg = (
                    "no calibration to check against: set the parameter verify_calibration "
                    "(a calibration JSON written by robocal-uncertainty calibrate --json)"
                )
                raise ConfigError(msg)
            campaign = self.store.pipeline().campaign
            if campaign is None:
                msg = "no samples held: measure the check poses (5-20 spread over the workspace) first"
                raise InputError(msg)
            run = verify(
                self.model,
                Path(path).expanduser(),
                campaign,
                check_name=str(self.campaign_path),
                retool=bool(get("verify_retool")),
                significance=float(get("verify_significance")),
                null_trials=int(get("verify_null_trials")),
                seed=int(get("verify_seed")),
            )
        except CalibError as err:
            reason = " ".join(str(err).split())  # one line
            self._check = {"error": reason, "stamp_ns": stamp}
            self.get_logger().error(f"verify refused ({len(self.store)} samples): {reason}")
            return False, f"refused: {reason}"
        result = run.verification
        summary = verification_summary(result)
        self._check = {"run": run, "summary": summary, "stamp_ns": stamp}
        for line in verification_lines(result, scope=run.scope_text):
            self.get_logger().info(f"verify: {line}")
        data = verification_to_dict(
            result,
            calibration=path,
            check_campaign=run.check_campaign,
            robot=self.model.name,
            scope=run.scope,
        )
        data.update(summary=summary, stamp_ns=stamp)
        self._verification_pub.publish(String(data=json.dumps(data)))
        try:
            write_verification_report(
                result,
                self.verify_report_dir,
                calibration=path,
                check_campaign=run.check_campaign,
                robot=self.model.name,
                scope=run.scope,
            )
        except OSError as err:
            self.get_logger().error(f"cannot write the verify report to {self.verify_report_dir}: {err}")
            summary += f" (report not written: {err})"
        return True, summary

    def _publish_description(self, result: IdentificationResult) -> None:
        """The calibrated URDF on the latched ``~/robot_description`` (for robot_description topic readers)."""
        try:
            source = self._source
            data = calibration_to_dict(result, robot=self.robot_config)
            text = calibrated_robot_description(data, source, urdf_text=self._description or None)
        except CalibError as err:
            self._causes.warning("no_robot_description", f"no calibrated robot_description: {err}")
            return
        self._description_pub.publish(String(data=text))

    def _write(self, result: IdentificationResult) -> None:
        data = calibration_to_dict(result, robot=self.robot_config)
        data["campaign_path"] = str(self.campaign_path)
        header = (
            "# Calibrated robot model written by robocal_uncertainty calibration_node.\n"
            "# Units: lengths in m, angles in rad (each parameter states its unit); residuals in m;\n"
            "# lambda in the column-scaled units of the identification (dimensionless).\n"
        )
        self.calibration_path.parent.mkdir(parents=True, exist_ok=True)
        temporary = self.calibration_path.with_name(self.calibration_path.name + ".tmp")
        temporary.write_text(header + yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        os.replace(temporary, self.calibration_path)


def main(args: Sequence[str] | None = None) -> int:
    """``ros2 run robocal_uncertainty calibration_node``."""
    return run_node(CalibrationNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
