"""Uncertainty node: each new calibration -> Monte Carlo (JCGM 101) tool-position uncertainty.

Inputs: ``robocal/calibration`` (the trigger; transient local, so a restarted node gets the
latest) and the samples, from ``robocal/samples`` plus the campaign file read at start (see
:mod:`robocal_uncertainty.nodes.common`). A ``CalibrationResult`` of n samples is
evaluated on the n earliest samples, the campaign the calibration node identified from; the
node re-identifies it with the calibration's own lambda method and warns if its estimate
differs from the published one. It waits for samples still in transit.

The evaluation (:func:`robocal_uncertainty.app.evaluate` on the pipeline's campaign and
calibration, the call the command line's ``evaluate``/``replay`` make, so the same settings
give the same numbers bit for bit; with ``budget``/``sweeps`` also the per-source budget and
the sweeps, summarised in the status JSON) runs in a worker thread: callbacks never block.
With ``workers`` > 1 the trial blocks run on worker processes started once, when the node
starts, and kept for every evaluation (:class:`~robocal_uncertainty.montecarlo.executor.WorkerPool`):
a new sample does not wait for fresh processes.
A newer calibration, or a change of a Monte Carlo parameter, supersedes the running
evaluation: it is cancelled at its next progress report (every ``block_size`` = 10 000
trials) and its result, if any, discarded.

Outputs, all reliable + transient local with one message per test configuration kept (a
late joiner gets the latest full set):

* ``robocal/uncertainty``: ``robocal_uncertainty/PoseUncertainty``, one per configuration.
* ``robocal/pose_with_covariance``: ``geometry_msgs/PoseWithCovarianceStamped``, one per
  configuration, in the frame set by ``output_frame`` (default: the frame of the campaign's points,
  e.g. the tracker's; ``base``: the robot base frame): position = Monte Carlo mean; orientation =
  the chordal mean of the Monte Carlo tool rotations. Covariance (6x6 row-major over x, y, z,
  rot x, rot y, rot z about the fixed axes, ROS convention): the full Monte Carlo pose
  covariance [m^2, m rad, rad^2] with the position-rotation correlation; only along rotation
  directions the campaign cannot determine (e.g. about the tool axis from points only) the
  variance is ``orientation_variance_rad2`` (default 1e6 rad^2, "unknown"), without
  correlation (``bagio.messages.pose_with_covariance``).
* ``robocal/uncertainty_status``: ``std_msgs/String`` JSON (state, trials done, target,
  sample count, ``sample_to_result_s``: from the newest sample's stamp to publication);
  progress is also logged every ``progress_period_s``.
* ``robocal/uncertainty_markers``: ``visualization_msgs/MarkerArray`` for RViz, latched: per
  test configuration the JCGM 102 coverage ellipsoid, magnified (``marker_scale``, the scale
  written in its label), and the campaign's measured points, in the result's frame
  (:mod:`robocal_uncertainty.pipeline.markers`).
* ``/diagnostics``: ``diagnostic_msgs/DiagnosticArray`` every ``diagnostics_period_s`` (state,
  trials, Monte Carlo convergence, largest u, evaluation time; OK/WARN/ERROR).

Service ``~/suggest_poses`` (``robocal_uncertainty/srv/SuggestPoses``): next-best calibration
poses for the latest evaluated campaign (:func:`robocal_uncertainty.app.suggest_poses`).

Service ``~/compensate_targets`` (``robocal_uncertainty/srv/CompensateTargets``): joints that reach
a ``geometry_msgs/PoseArray`` of targets under the latest evaluated calibration, and the stated
uncertainty of the reached positions with this node's Monte Carlo settings
(:func:`robocal_uncertainty.app.compensate`). It lives here, not in the calibration node, because
this node holds the evaluated campaign, its calibration and the statement's settings.
"""

from __future__ import annotations

from robocal_uncertainty._threads import limit_threads

# The command line's thread policy, so the node computes the command line's numbers; before
# numpy loads its BLAS.
limit_threads()

import json
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from robocal_uncertainty.app import Evaluation, evaluate
from robocal_uncertainty.app.campaign_checks import check_campaign_joints
from robocal_uncertainty.app.pose_suggestion import service_arguments, service_response, suggest_poses
from robocal_uncertainty.bagio.messages import msg_to_sample, pose_with_covariance, uncertainty_to_msgs
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.sample import CalibrationSample
from robocal_uncertainty.errors import CalibError, ConfigError
from robocal_uncertainty.montecarlo.executor import RunContext, WorkerPool
from robocal_uncertainty.msg import CalibrationResult as CalibrationResultMsg
from robocal_uncertainty.msg import CalibrationSample as CalibrationSampleMsg
from robocal_uncertainty.msg import PoseUncertainty as PoseUncertaintyMsg
from robocal_uncertainty.nodes.common import (
    CauseLogger,
    campaign_file,
    diagnostic_array,
    load_model,
    marker_array,
    run_node,
    stamp_ns,
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
)
from robocal_uncertainty.nodes.qos import DIAGNOSTICS_QOS, SAMPLE_QOS, latched_qos
from robocal_uncertainty.pipeline.diagnostics import DiagnosticStatus, uncertainty_status
from robocal_uncertainty.pipeline.markers import uncertainty_markers
from robocal_uncertainty.pipeline.sample_store import SampleStore
from robocal_uncertainty.report.references import PAPER_TEST_JOINTS_DEG
from robocal_uncertainty.srv import CompensateTargets, SuggestPoses
from robocal_uncertainty.uncertainty import (
    CalibrationUncertainty,
    EvaluationSettings,
    default_sources,
    parse_sources,
    sources_help,
)
from robocal_uncertainty.uncertainty.calibration.settings import build_evaluation_settings, build_source_settings
from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY, SourceOption, source_parameters

__all__ = ["PARAMETERS", "UncertaintyNode", "main"]

_LATENCY_LIMIT_S = 3600.0
"""A sample older than this on the node's clock is on another clock (a recording's)."""
_CLOCK_SLACK_S = 1.0
"""Stamps this far ahead of the node's clock are tolerated (clock offsets between machines)."""

# Parameters whose change re-runs the latest calibration's evaluation.
_MONTE_CARLO = frozenset(
    {
        "sources",
        "trials",
        "max_trials",
        "n_dig",
        "seed",
        "coverage",
        *(parameter.name for parameter in source_parameters()),
        "tracker_xyz_m",
        "output_frame",
        "accept_unconverged",
        "budget",
        "budget_trials",
        "sweeps",
        "sweep_trials",
    }
)


def source_options_all() -> tuple[SourceOption, ...]:
    """The options of every registered source (each gives its value from the node's parameters)."""
    return tuple(option for spec in SOURCE_REGISTRY.values() for option in spec.options)


def _sources(value: Any) -> str | None:
    try:
        parse_sources(str(value))
    except ConfigError as err:
        return str(err)
    return None


def _numbers(value: Any) -> str | None:
    if not isinstance(value, (list, tuple)) or not value:
        return "must be a non-empty list of numbers"
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in value):
        return f"must hold finite numbers only, got {list(value)}"
    return None


def _joints(value: Any) -> str | None:
    return None if value is None else _numbers(value)


def _xyz(value: Any) -> str | None:
    reason = _numbers(value)
    if reason is None and len(value) != 3:
        reason = f"must have 3 values (x, y, z), got {len(value)}"
    return reason


def _output_frame(value: Any) -> str | None:
    return None if value in ("measurement", "base") else f"must be 'measurement' or 'base', got {value!r}"


def _backend(value: Any) -> str | None:
    from robocal_uncertainty.errors import ConfigError
    from robocal_uncertainty.kernels import get_backend

    try:
        get_backend(str(value))
    except ConfigError as err:
        return str(err)
    return None


PARAMETERS: tuple[ParamSpec, ...] = (
    ROBOT_CONFIG,
    BASE_UNKNOWN,
    CAMPAIGN_PATH_READ,
    READ_CAMPAIGN_AT_START,
    ParamSpec(
        "test_joints_deg",
        None,
        "Test joint configurations in DEGREES, n_joints values per configuration, flattened; one result per "
        "configuration (fixed at start); set this or test_joints_rad, not both; neither: the robot paper's "
        "test configuration (Jiang et al. Table 2)",
        "deg",
        read_only=True,
        check=_joints,
        dynamic_typing=True,
    ),
    ParamSpec(
        "test_joints_rad",
        None,
        "Test joint configurations in RADIANS, n_joints values per configuration, flattened; set this or "
        "test_joints_deg, not both",
        "rad",
        read_only=True,
        check=_joints,
        dynamic_typing=True,
    ),
    ParamSpec(
        "sources",
        ",".join(default_sources()),
        f"Comma list of uncertainty sources: {sources_help()} (default: the validated set; "
        "add tracker_orientation for a 6-DOF tracker)",
        check=_sources,
    ),
    ParamSpec(
        "trials", 0, "Monte Carlo trials M; 0 = JCGM 101 7.9 adaptive procedure", "trials", low=0, high=100_000_000
    ),
    ParamSpec("max_trials", 2_000_000, "Cap of the adaptive procedure", "trials", low=20_000, high=1_000_000_000),
    ParamSpec("n_dig", 2, "Significant digits of the adaptive procedure", "digits", low=1, high=4),
    ParamSpec("seed", 0, "Root seed of the random streams (same seed, same numbers)", low=0, high=2**62),
    ParamSpec("coverage", 0.95, "Coverage probability p of the intervals", "", low=0.5, high=0.9999),
    # The settings of every registered source (noise models, lambda range, pose counts, model error).
    *(
        ParamSpec(
            parameter.name,
            parameter.default,
            parameter.description,
            parameter.unit,
            low=parameter.low,
            high=parameter.high,
        )
        for parameter in source_parameters()
    ),
    # Before the field became the default; read only to say so (an old parameter file keeps working).
    ParamSpec(
        "model_error_field",
        None,
        "No longer read: the model error is a field over the joint configurations by default "
        "(independent_model_error: true draws it from pose to pose)",
        read_only=True,
        dynamic_typing=True,
    ),
    ParamSpec(
        "tracker_xyz_m",
        [2.0, 0.5, 0.3],
        "Tracker position in the robot base frame, for MPE distances of base-frame campaigns",
        "m",
        check=_xyz,
        dynamic_typing=True,
    ),
    ParamSpec(
        "output_frame",
        "measurement",
        "Frame of the published poses: 'measurement' (the campaign's points' frame, e.g. the tracker's; the base "
        "transform's uncertainty enters) or 'base' (the robot base frame)",
        "",
        check=_output_frame,
    ),
    ParamSpec(
        "accept_unconverged",
        False,
        "Evaluate an identification that did not converge instead of reporting the failure",
    ),
    ParamSpec(
        "field_correction",
        False,
        "Add the model-error field's conditional mean given the calibration residuals (kriging) to every published "
        "position, with the kriging covariance in its statement (as evaluate --field-correction); helps near the "
        "calibration poses of a dense campaign, fades far from them, holds in this session only; a calibration "
        "whose model explains its points has no field and the evaluation fails with that reason",
    ),
    ParamSpec("budget", False, "Also run each source alone (uncertainty budget; two or more sources)"),
    ParamSpec("budget_trials", 2000, "Trials of each budget run", "trials", low=1, high=100_000_000),
    ParamSpec("sweeps", False, "Also compute u against lambda and against the number of equations"),
    ParamSpec("sweep_trials", 300, "Trials per sweep point", "trials", low=1, high=100_000_000),
    ParamSpec(
        "workers",
        1,
        "Monte Carlo worker processes, started once and kept (1: in the node's process; never changes the result)",
        "processes",
        True,
        1,
        256,
    ),
    ParamSpec(
        "backend",
        "auto",
        "Monte Carlo trial kernels: numpy (reference), numba (compiled, extra 'fast'), cupy (GPU, extra 'gpu') or "
        "auto (the fastest installed); the same result to 1e-12 relative",
        "",
        check=_backend,
    ),
    ParamSpec("progress_period_s", 2.0, "Interval of progress reports", "s", low=0.1, high=3600.0),
    ParamSpec(
        "orientation_variance_rad2",
        1e6,
        "Variance put on the undetermined rotation directions of pose_with_covariance",
        "rad^2",
        low=0.0,
        high=1e12,
    ),
    DIAGNOSTICS_PERIOD,
    ParamSpec(
        "marker_scale",
        0.0,
        "Magnification of the coverage ellipsoids in robocal/uncertainty_markers; 0 = the power of ten drawing "
        "the largest at about marker_size_m (the scale is written in each marker's label)",
        "",
        low=0.0,
        high=1e12,
    ),
    ParamSpec(
        "marker_size_m", 0.05, "Drawn size of the largest ellipsoid with marker_scale 0", "m", low=1e-4, high=10.0
    ),
)


def _extras(evaluation: Evaluation) -> dict[str, Any]:
    """Budget and sweeps of the first test configuration for the status JSON, in um."""
    out: dict[str, Any] = {}
    if evaluation.budget:
        out["budget_u_um"] = {
            source: [round(a.standard_uncertainty * 1e6, 4) for a in run.poses[0].axes]
            for source, run in evaluation.budget.items()
        }
    for sweep in evaluation.sweeps:
        out[f"sweep_{sweep.name}"] = {
            "values": sweep.values.tolist(),
            "u_um": np.round(sweep.standard_uncertainty * 1e6, 4).tolist(),
        }
    return out


class _Superseded(Exception):
    """Raised in the progress callback to abandon a stale evaluation."""


@dataclass(frozen=True)
class _Job:
    generation: int
    samples: tuple[CalibrationSample, ...]
    calibration: CalibrationResultMsg
    options: EvaluationSettings
    field_correction: bool = False


class UncertaintyNode(Node):
    """The Monte Carlo evaluation as a ROS 2 node (see the module docstring)."""

    def __init__(self, *, node_name: str = "uncertainty_node", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._rerun = False
        p = declare_parameters(self, PARAMETERS, on_change=self._note_change)
        if p["model_error_field"] is not None:
            self.get_logger().warning(
                f"parameter model_error_field ({p['model_error_field']}) is no longer read: the model error is a "
                "field over the joint configurations by default; independent_model_error: true draws it from pose "
                "to pose"
            )
        self.model = load_model(p["robot_config"], base_unknown=p["base_unknown"])
        n = self.model.n_joints
        degrees, radians = p["test_joints_deg"], p["test_joints_rad"]
        if degrees is not None and radians is not None:
            raise ConfigError("parameters test_joints_deg and test_joints_rad are both set: give one")
        name = "test_joints_rad" if radians is not None else "test_joints_deg"
        given = radians if radians is not None else degrees if degrees is not None else PAPER_TEST_JOINTS_DEG
        values = np.array(given, dtype=np.float64)
        if values.size % n:
            msg = f"parameter {name}: {values.size} values are not a multiple of the {n} joints"
            raise ConfigError(msg)
        q = values.reshape(-1, n)
        self.test_joints = q if radians is not None else np.radians(q)
        self.store = SampleStore(self.model)
        self.campaign_path = campaign_file(p["campaign_path"])
        self._causes = CauseLogger(self, 5.0)
        if p["read_campaign_at_start"] and self.campaign_path.exists():
            try:
                added, notes = self.store.load_campaign_file(self.campaign_path)
            except CalibError as err:
                self.get_logger().error(f"cannot read campaign {self.campaign_path}: {err}")
            else:
                for note in notes:
                    self.get_logger().warning(f"campaign {self.campaign_path}: {note}")
                self.get_logger().info(f"read {added} samples from {self.campaign_path}")

        depth = self.test_joints.shape[0]
        self._uncertainty_pub = self.create_publisher(PoseUncertaintyMsg, "robocal/uncertainty", latched_qos(depth))
        self._pose_pub = self.create_publisher(
            PoseWithCovarianceStamped, "robocal/pose_with_covariance", latched_qos(depth)
        )
        self._status_pub = self.create_publisher(String, "robocal/uncertainty_status", latched_qos())
        self._marker_pub = self.create_publisher(MarkerArray, "robocal/uncertainty_markers", latched_qos())
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
        self._health: dict[str, Any] = {"state": "idle"}
        # Started by the worker thread; the trial block's module is imported once per process.
        self._pool = WorkerPool(int(p["workers"]), preload=("robocal_uncertainty.uncertainty.calibration.evaluation",))
        self._evaluated: tuple[Campaign, IdentificationResult, EvaluationSettings] | None = None
        self.create_service(SuggestPoses, "~/suggest_poses", self._suggest_poses)
        self.create_service(CompensateTargets, "~/compensate_targets", self._compensate_targets)
        self.create_subscription(CalibrationSampleMsg, "robocal/samples", self._on_sample, SAMPLE_QOS)
        self.create_subscription(CalibrationResultMsg, "robocal/calibration", self._on_calibration, latched_qos())

        self._latest: CalibrationResultMsg | None = None
        self._waiting = False
        self._generation = 0
        self._pending: _Job | None = None
        self._stop = False
        self._wake = threading.Condition()
        self.completed = 0
        self._worker = threading.Thread(target=self._work, name="robocal_monte_carlo", daemon=True)
        self._worker.start()
        self.create_timer(0.25, self._after_parameter_change)
        self.create_timer(p["diagnostics_period_s"], self._publish_diagnostics)
        self._status({"state": "idle", "samples": len(self.store)})
        self.get_logger().info(f"evaluating {depth} test configuration(s) of {self.model.name} on each new calibration")

    # -- input -----------------------------------------------------------------------------

    def _on_sample(self, msg: CalibrationSampleMsg) -> None:
        try:
            added = self.store.add(msg_to_sample(msg))
        except CalibError as err:
            self._causes.warning("bad_sample", f"sample dropped: {err}")
            return
        if added and self._waiting:
            self._submit()

    def _on_calibration(self, msg: CalibrationResultMsg) -> None:
        self._latest = msg
        self._submit()

    def _note_change(self, parameters: list[Parameter]) -> None:
        if any(parameter.name in _MONTE_CARLO for parameter in parameters):
            self._rerun = True  # applied by rclpy after this returns; re-run from the timer

    def _after_parameter_change(self) -> None:
        if self._rerun:
            self._rerun = False
            if self._latest is not None:
                self.get_logger().info("Monte Carlo settings changed: re-evaluating the latest calibration")
                self._submit()

    def _sources_for(self, measures_orientation: bool) -> str:
        """The ``sources`` parameter; at its default, a 6-DOF campaign adds its orientation noise
        (``tracker_orientation``), as ``evaluate``, ``validate`` and ``replay`` do."""
        given = str(self.get_parameter("sources").value)
        default = next(spec.default for spec in PARAMETERS if spec.name == "sources")
        if given == default and measures_orientation:
            # The registry's default set of a campaign with orientations (as the commands use).
            return ",".join(default_sources(measures_orientation=True))
        return given

    def _options(self, msg: CalibrationResultMsg, *, measures_orientation: bool = False) -> EvaluationSettings:
        """The :class:`EvaluationSettings` of the parameters, with the calibration's lambda choice
        (built by the same functions as the command line's options)."""

        def get(name: str) -> Any:
            return self.get_parameter(name).value

        # Every registered source's options from its parameters (each source turns its own into settings).
        parameters = {parameter.name: get(parameter.name) for parameter in source_parameters()}
        settings = build_source_settings(
            sources=self._sources_for(measures_orientation),
            values={option.dest: option.from_parameters(parameters) for option in source_options_all()},
            tracker_xyz_m=get("tracker_xyz_m"),
        )
        trials = int(get("trials"))
        return build_evaluation_settings(
            settings,
            lambda_=self._lambda_of(msg),
            test_joints=self.test_joints,
            trials=trials if trials > 0 else "auto",
            seed=int(get("seed")),
            coverage=float(get("coverage")),
            n_dig=int(get("n_dig")),
            max_trials=int(get("max_trials")),
            frame=str(get("output_frame")),
            accept_unconverged=bool(get("accept_unconverged")),
            budget=bool(get("budget")),
            budget_trials=int(get("budget_trials")),
            sweeps=bool(get("sweeps")),
            sweep_trials=int(get("sweep_trials")),
            backend=str(get("backend")),
        )

    def _submit(self) -> None:
        """Queue the evaluation of the latest calibration (superseding any other)."""
        msg = self._latest
        if msg is None:
            return
        need = int(msg.sample_count)
        if len(self.store) < need:
            if not self._waiting:
                self.get_logger().info(f"calibration of {need} samples: waiting for samples ({len(self.store)} held)")
            self._waiting = True
            self._status({"state": "waiting_for_samples", "samples": len(self.store), "sample_count": need})
            return
        self._waiting = False
        samples = tuple(self.store.first(need))
        try:
            options = self._options(msg, measures_orientation=bool(samples) and samples[0].orientation is not None)
        except CalibError as err:
            self.get_logger().error(f"invalid Monte Carlo settings: {err}")
            self._status({"state": "failed", "error": f"invalid Monte Carlo settings: {err}"})
            return
        with self._wake:
            self._generation += 1
            correct = bool(self.get_parameter("field_correction").value)
            self._pending = _Job(self._generation, samples, msg, options, correct)
            self._wake.notify()

    # -- worker ----------------------------------------------------------------------------

    def _work(self) -> None:
        try:
            self._pool.start()
        except Exception as err:  # the first evaluation retries; report, do not die
            self.get_logger().error(f"cannot start the Monte Carlo worker processes: {type(err).__name__}: {err}")
        while True:
            with self._wake:
                while self._pending is None and not self._stop:
                    self._wake.wait()
                if self._stop:
                    return
                job, self._pending = self._pending, None
            assert job is not None  # the wait above ends with a job or with _stop
            try:
                self._run(job)
            except Exception as err:
                self.get_logger().error(f"uncertainty evaluation failed: {type(err).__name__}: {err}")
                self._status({"state": "failed", "error": str(err)})

    def _progress_of(self, job: _Job, started: float) -> Callable[[int, int | None], None]:
        """The progress callback of `job`'s main run: logs and status every progress_period_s,
        and abandons the run (raising :class:`_Superseded`) once a newer job is queued."""
        n = len(job.samples)
        period = float(self.get_parameter("progress_period_s").value)
        last = [started]

        def progress(done: int, target: int | None) -> None:
            if self._stop or job.generation != self._generation:
                raise _Superseded
            now = time.monotonic()
            if now - last[0] >= period:
                last[0] = now
                of = f"/{target}" if target else " (adaptive)"
                self.get_logger().info(f"Monte Carlo of the {n}-sample calibration: {done}{of} trials")
                self._status({"state": "running", "done": done, "target": target, "sample_count": n})

        return progress

    def _latency_s(self, job: _Job) -> float | None:
        """Seconds from the newest sample's stamp (when the pose was taken) to now, on this node's
        clock; None (with a warning) when the stamps are not on it."""
        # A played recording needs `ros2 bag play --clock` and use_sim_time, else its stamps are
        # not on the node's clock and no latency is stated.
        newest = max(sample.stamp_ns for sample in job.samples)
        latency = (self.get_clock().now().nanoseconds - newest) / 1e9
        if not (-_CLOCK_SLACK_S <= latency <= _LATENCY_LIMIT_S):
            self._causes.warning(
                "clock",
                f"sample stamps are {latency:.3g} s from this node's clock: no sample_to_result_s "
                "(playing a recording? use `ros2 bag play --clock` and use_sim_time:=true)",
            )
            return None
        return float(latency)

    def _run(self, job: _Job) -> None:
        n = len(job.samples)
        started = time.monotonic()
        progress = self._progress_of(job, started)
        self._status({"state": "running", "done": 0, "target": job.options.trials, "sample_count": n})
        pipeline = SampleStore.pipeline_of(self.model, job.samples, options=job.options)
        try:
            campaign = pipeline.campaign
            if campaign is not None:
                # The command line's check of a campaign file, on the samples: readings outside
                # the joint limits (degrees sent as radians) are refused, not calibrated.
                check_campaign_joints(self.model, campaign, f"the {n}-sample campaign")
            calibration = pipeline.calibrate()
            assert campaign is not None  # calibrate() refuses a pipeline without samples
            evaluation = evaluate(
                self.model,
                campaign,
                job.options,
                calibration=calibration,
                run=RunContext(executor=self._pool.executor(), progress=progress),
                field_correction=job.field_correction,
            )
        except _Superseded:
            self.get_logger().info(f"Monte Carlo of the {n}-sample calibration superseded; abandoned")
            return
        except CalibError as err:
            self._causes.warning("evaluation_failed", f"Monte Carlo of the {n}-sample calibration failed: {err}")
            self._status({"state": "failed", "sample_count": n, "error": str(err)})
            return
        if self._stop or job.generation != self._generation:
            self.get_logger().info(f"Monte Carlo of the {n}-sample calibration superseded; result discarded")
            return
        result = evaluation.uncertainty
        for warning in evaluation.input_warnings:
            self._causes.warning("input_warning", warning)
        if result.not_converged:
            # As on the command line: trials that did not re-identify the calibration are no
            # statement, so nothing is published (the last good statement stays latched).
            error = (
                f"the Monte Carlo of the {n}-sample calibration did not converge to a statement: "
                f"{result.not_converged[0]}; nothing published"
            )
            self._causes.warning("evaluation_failed", error)
            self._status({"state": "failed", "sample_count": n, "error": error})
            return
        self._check_same_calibration(result, job.calibration)
        self._publish(result, job.calibration)
        campaign = pipeline.campaign
        assert campaign is not None  # pipeline_of holds the job's samples
        self._publish_markers(result, campaign, job.calibration)
        self._evaluated = (campaign, calibration, job.options)
        self.completed += 1
        elapsed = time.monotonic() - started
        latency = self._latency_s(job)
        self._health = {
            "state": "done",
            "trials": result.n_trials,
            "converged": result.converged,
            "max_u": max(float(a.standard_uncertainty) for pose in result.poses for a in pose.axes),
            "finished_ns": self.get_clock().now().nanoseconds,
            "elapsed_s": elapsed,
            "latency_s": latency,
            "trust_note": result.model_adequacy.trust_note,
        }
        u = result.poses[0].axes
        self.get_logger().info(
            f"uncertainty of the {n}-sample calibration: {result.n_trials} trials in {elapsed:.1f} s; "
            f"first configuration u(x, y, z) = (" + ", ".join(f"{a.standard_uncertainty * 1e6:.3f}" for a in u) + ") um"
        )
        self._status(
            {
                "state": "done",
                "sample_count": n,
                "trials": result.n_trials,
                "converged": result.converged,
                "elapsed_s": round(elapsed, 3),
                "sample_to_result_s": None if latency is None else round(latency, 3),
                **_extras(evaluation),
            }
        )

    @staticmethod
    def _lambda_of(msg: CalibrationResultMsg) -> str | float:
        """The calibration node's lambda choice, so the re-identification is the same."""
        if msg.lambda_method == "fixed":
            return float(msg.lambda_value)
        return "gcv" if msg.lambda_method == "gcv" else "auto"

    def _check_same_calibration(self, result: CalibrationUncertainty, msg: CalibrationResultMsg) -> None:
        mine = np.asarray(result.calibration.estimate, dtype=np.float64)
        theirs = np.asarray(msg.estimate, dtype=np.float64)
        if mine.shape != theirs.shape or not np.array_equal(mine, theirs):
            diff = float(np.max(np.abs(mine - theirs))) if mine.shape == theirs.shape else float("nan")
            self.get_logger().warning(
                "the evaluated calibration differs from the published one "
                f"(max |difference| {diff:.3g}): the samples held differ from the calibration node's"
            )

    def _publish(self, result: CalibrationUncertainty, msg: CalibrationResultMsg) -> None:
        stamp = stamp_ns(msg.header)
        frame_id = result.frame_id  # the frame the positions are in (measurement or base)
        variance = float(self.get_parameter("orientation_variance_rad2").value)
        for message, pose in zip(uncertainty_to_msgs(result, stamp_ns=stamp, frame_id=frame_id), result.poses):
            self._uncertainty_pub.publish(to_ros(message, PoseUncertaintyMsg))
            out = PoseWithCovarianceStamped()
            out.header.stamp = msg.header.stamp
            out.header.frame_id = frame_id
            # The full 6x6 (ROS convention, rad^2): huge variance only along undetermined rotations.
            position, quaternion, covariance = pose_with_covariance(pose, undetermined_variance=variance)
            out.pose.pose.position.x, out.pose.pose.position.y, out.pose.pose.position.z = (float(v) for v in position)
            o = out.pose.pose.orientation
            o.x, o.y, o.z, o.w = (float(v) for v in quaternion)
            out.pose.covariance = covariance.reshape(-1).tolist()
            self._pose_pub.publish(out)

    def _status(self, state: dict[str, Any]) -> None:
        if state.get("state") != "done":  # "done" carries the result; _run records it
            self._health = {**self._health, "state": state.get("state", "idle"), "error": state.get("error")}
        self._status_pub.publish(String(data=json.dumps(state, sort_keys=True)))

    def _publish_markers(self, result: CalibrationUncertainty, campaign: Campaign, msg: CalibrationResultMsg) -> None:
        scale = float(self.get_parameter("marker_scale").value)
        # A 6-DOF campaign stores n x 12 pose values: the markers show their positions.
        specs = uncertainty_markers(
            result,
            campaign_points=campaign.measurement.positions(campaign.points),
            campaign_frame=campaign.frame,
            scale=scale or None,
            target_size_m=float(self.get_parameter("marker_size_m").value),
        )
        self._marker_pub.publish(marker_array(specs, msg.header.stamp))

    def diagnostic_status(self) -> DiagnosticStatus:
        """The evaluation's health (rules in :mod:`robocal_uncertainty.pipeline.diagnostics`)."""
        health = self._health
        return uncertainty_status(
            name=f"{self.get_name()}: Monte Carlo",
            hardware_id=self.model.name,
            now_ns=self.get_clock().now().nanoseconds,
            state=str(health.get("state", "idle")),
            samples=len(self.store),
            trials=health.get("trials"),
            converged=health.get("converged"),
            max_standard_uncertainty_m=health.get("max_u"),
            last_evaluation_ns=health.get("finished_ns"),
            last_evaluation_s=health.get("elapsed_s"),
            error=health.get("error"),
            trust_note=health.get("trust_note") or "",
        )

    def _publish_diagnostics(self) -> None:
        self._diagnostics_pub.publish(diagnostic_array(self, [self.diagnostic_status()]))

    def _suggest_poses(self, request: SuggestPoses.Request, response: SuggestPoses.Response) -> SuggestPoses.Response:
        """Next-best poses for the latest evaluated campaign (blocks this node's callbacks
        while it runs: milliseconds for the ranking, plus any Monte Carlo checks asked for)."""
        evaluated = self._evaluated
        if evaluated is None:
            response.success = False
            response.message = "no evaluated calibration yet"
            return response
        campaign, calibration, options = evaluated
        try:
            arguments = service_arguments(
                n_joints=self.model.n_joints,
                count=request.count,
                candidates=list(request.candidates),
                candidate_count=request.candidate_count,
                monte_carlo_check=request.monte_carlo_check,
                trials=request.trials,
                seed=request.seed,
            )
            result = suggest_poses(
                self.model,
                campaign,
                self.test_joints,
                settings=options.uncertainty,
                calibration=calibration,
                lambda_=options.lambda_,
                frame=options.frame,
                backend=options.backend,  # the node's trial kernels for the Monte Carlo checks
                **arguments,  # type: ignore[arg-type]
            )
        except CalibError as err:
            response.success = False
            response.message = str(err)
            return response
        for name, value in service_response(result).items():
            setattr(response, name, value)
        self.get_logger().info(f"suggest_poses: {response.message}")
        return response

    def _compensate_targets(
        self, request: CompensateTargets.Request, response: CompensateTargets.Response
    ) -> CompensateTargets.Response:
        """Compensated joint targets for the latest evaluated calibration (blocks this node's
        callbacks while its Monte Carlo runs)."""
        from dataclasses import replace

        from robocal_uncertainty.app.compensation import compensate, service_response, service_targets
        from robocal_uncertainty.core.calibration_file import apply_calibration, calibration_to_dict

        evaluated = self._evaluated
        if evaluated is None:
            response.success = False
            response.message = "no evaluated calibration yet"
            return response
        campaign, calibration, options = evaluated
        try:
            data = calibration_to_dict(calibration, robot=self.model.name)
            poses = request.targets.poses
            targets, frame, seeds = service_targets(
                positions=np.array([[p.position.x, p.position.y, p.position.z] for p in poses]),
                quaternions=np.array(
                    [[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w] for p in poses]
                ),
                use_orientation=bool(request.use_orientation),
                frame_id=str(request.targets.header.frame_id),
                model=self.model,
                calibrated=apply_calibration(self.model, data),
                seed_joints=list(request.seed_joints),
            )
            run = replace(options, seed=int(request.seed), trials=int(request.trials) or options.trials)
            result = compensate(
                self.model, data, targets, frame=frame, seeds=seeds, campaign=campaign, options=run, where="calibration"
            )
        except CalibError as err:
            response.success = False
            response.message = str(err)
            return response
        for name, value in service_response(result).items():
            setattr(response, name, value)
        self.get_logger().info(f"compensate_targets: {response.message}")
        return response

    def destroy_node(self) -> None:
        with self._wake:
            self._stop = True
            self._wake.notify()
        self._worker.join(timeout=10.0)
        self._pool.close()
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    """``ros2 run robocal_uncertainty uncertainty_node``."""
    return run_node(UncertaintyNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
