"""Health of the online pipeline as diagnostic statuses (ROS-free).

Each node turns its state into one :class:`DiagnosticStatus` with a level (OK, WARN,
ERROR, STALE: the values of ``diagnostic_msgs/DiagnosticStatus``), a one-line message and
key values, and publishes them periodically as ``diagnostic_msgs/DiagnosticArray`` on
``/diagnostics`` (``rqt_robot_monitor``, the diagnostic aggregator and fleet monitoring read
that topic). The rules live here, so CI tests them without ROS:

* collector: samples, messages received and dropped per cause, rejected dwells, time since
  the last sample and since the last input message. ERROR when a sample could not be
  recorded; WARN when no input arrived yet or an input stream fell silent, or when more
  than ``drop_warn_fraction`` of the messages were dropped.
* calibration: samples, condition number, residual RMS, lambda, time since the last
  calibration. ERROR when the last calibration failed or did not converge; WARN while too
  few samples are held, or when the condition number or the residual RMS exceeds its limit.
* verification (the calibration node's ``~/verify``): the last check's verdict, p-value and
  tracker move. OK when consistent (or none run yet), WARN when drifted, ERROR when the
  check was refused (no or an unusable calibration file, too few or degenerate poses).
* uncertainty: state, trials, Monte Carlo convergence, largest standard uncertainty, whether
  the statement is trustworthy, time the last evaluation took and since it finished. ERROR
  when it failed; WARN while none finished yet, when the adaptive procedure did not converge,
  or when the campaign is too small for a trustworthy statement (``ModelAdequacy.trust_note``).

Times are int ns on the node's clock; values are SI (s, m), written with their unit in the
key, e.g. ``residual_rms_m``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum

from robocal_uncertainty.errors import ConfigError

__all__ = [
    "DiagnosticLevel",
    "DiagnosticStatus",
    "DiagnosticThresholds",
    "calibration_status",
    "collector_status",
    "uncertainty_status",
    "verification_status",
]

_NS_PER_S = 1_000_000_000


class DiagnosticLevel(IntEnum):
    """Levels of ``diagnostic_msgs/DiagnosticStatus`` (same numbers)."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class DiagnosticStatus:
    """One component's health.

    Attributes
    ----------
    name : str
        ``<node name>: <component>``, as the aggregator groups them.
    hardware_id : str
        The robot model's name.
    level : DiagnosticLevel
    message : str
        One line: the worst finding, or ``"ok"``.
    values : tuple of (str, str)
        Key values, units in the keys.
    """

    name: str
    hardware_id: str
    level: DiagnosticLevel
    message: str
    values: tuple[tuple[str, str], ...]

    def value(self, key: str) -> str:
        """The value of `key` (KeyError when absent)."""
        for name, value in self.values:
            if name == key:
                return value
        raise KeyError(key)


@dataclass(frozen=True)
class DiagnosticThresholds:
    """Limits of the WARN findings.

    Parameters
    ----------
    input_timeout_s : float [s]
        An input stream silent for longer is reported (WARN).
    drop_warn_fraction : float
        Fraction of dropped input messages above which the collector warns.
    condition_warn : float
        Condition number of the scaled identification Jacobian above which the calibration
        warns (poorly conditioned: poses too alike).
    residual_rms_warn_m : float [m]
        Residual RMS after calibration above which the calibration warns (model or data
        problem).
    """

    input_timeout_s: float = 2.0
    drop_warn_fraction: float = 0.01
    condition_warn: float = 1e4
    residual_rms_warn_m: float = 1e-4

    def __post_init__(self) -> None:
        for name in ("input_timeout_s", "drop_warn_fraction", "condition_warn", "residual_rms_warn_m"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not (value > 0 and math.isfinite(value))
            ):
                msg = f"{name} must be a finite number > 0, got {value!r}"
                raise ConfigError(msg)


def _age_s(now_ns: int, then_ns: int | None) -> float | None:
    return None if then_ns is None else max(0, now_ns - then_ns) / _NS_PER_S


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None:
        return "n/a"
    return f"{value:.{digits}g}"


def _worst(findings: list[tuple[DiagnosticLevel, str]]) -> tuple[DiagnosticLevel, str]:
    if not findings:
        return DiagnosticLevel.OK, "ok"
    level = max(level for level, _ in findings)
    return level, "; ".join(text for lvl, text in findings if lvl == level)


def collector_status(
    *,
    name: str,
    hardware_id: str,
    now_ns: int,
    samples: int,
    received: Mapping[str, int],
    dropped: Mapping[str, int],
    rejected_dwells: int,
    record_failures: int,
    last_sample_ns: int | None,
    last_input_ns: Mapping[str, int | None],
    static: bool,
    thresholds: DiagnosticThresholds | None = None,
) -> DiagnosticStatus:
    """Status of the static-pose collector.

    Parameters
    ----------
    name, hardware_id : str
        See :class:`DiagnosticStatus`.
    now_ns : int [ns]
        Current time (node clock).
    samples : int
        Samples recorded in the campaign.
    received : mapping of str to int
        Messages received per input stream.
    dropped : mapping of str to int
        Messages dropped per cause (:data:`~robocal_uncertainty.pipeline.collector.DROP_CAUSES`).
    rejected_dwells, record_failures : int
        Dwells with too few data; samples that could not be written to the campaign file.
    last_sample_ns : int or None [ns]
        When the last sample was taken (None: none yet).
    last_input_ns : mapping of str to int or None [ns]
        When each input stream last delivered a message (None: never).
    static : bool
        The arm is in a static dwell now.
    thresholds : DiagnosticThresholds, optional

    Returns
    -------
    DiagnosticStatus
    """
    limits = thresholds or DiagnosticThresholds()
    findings: list[tuple[DiagnosticLevel, str]] = []
    if record_failures:
        findings.append((DiagnosticLevel.ERROR, f"{record_failures} sample(s) could not be recorded"))
    for stream, then in last_input_ns.items():
        age = _age_s(now_ns, then)
        if age is None:
            findings.append((DiagnosticLevel.WARN, f"no {stream} received yet"))
        elif age > limits.input_timeout_s:
            findings.append((DiagnosticLevel.WARN, f"{stream} silent for {age:.1f} s"))
    total_received = sum(received.values())
    total_dropped = sum(dropped.values())
    if total_received and total_dropped / total_received > limits.drop_warn_fraction:
        causes = ", ".join(f"{c} {n}" for c, n in sorted(dropped.items()) if n)
        findings.append((DiagnosticLevel.WARN, f"{total_dropped} of {total_received} messages dropped ({causes})"))
    level, message = _worst(findings)
    values = [
        ("samples", str(samples)),
        ("static", str(bool(static)).lower()),
        ("time_since_last_sample_s", _fmt(_age_s(now_ns, last_sample_ns))),
        *((f"received.{stream}", str(n)) for stream, n in sorted(received.items())),
        *((f"time_since_last_{stream}_s", _fmt(_age_s(now_ns, t))) for stream, t in sorted(last_input_ns.items())),
        ("dropped_total", str(total_dropped)),
        *((f"dropped.{cause}", str(n)) for cause, n in dropped.items()),
        ("rejected_dwells", str(rejected_dwells)),
        ("record_failures", str(record_failures)),
    ]
    return DiagnosticStatus(name, hardware_id, level, message, tuple(values))


def calibration_status(
    *,
    name: str,
    hardware_id: str,
    now_ns: int,
    samples: int,
    min_samples: int,
    last_calibration_ns: int | None,
    condition_number: float | None,
    residual_rms_m: float | None,
    lambda_: float | None,
    converged: bool | None,
    error: str | None = None,
    thresholds: DiagnosticThresholds | None = None,
) -> DiagnosticStatus:
    """Status of the calibration (identification) stage.

    Parameters
    ----------
    samples, min_samples : int
        Samples held and the count before the first calibration.
    last_calibration_ns : int or None [ns]
        When the last calibration finished (None: none yet).
    condition_number : float or None
        Of the column-scaled identification Jacobian of the last calibration.
    residual_rms_m : float or None [m]
        RMS point error after the last calibration.
    lambda_ : float or None
        Its regularisation parameter (column-scaled units).
    converged : bool or None
        Whether it converged (None: no calibration yet).
    error : str, optional
        Why the last attempt failed.
    """
    limits = thresholds or DiagnosticThresholds()
    findings: list[tuple[DiagnosticLevel, str]] = []
    if error:
        findings.append((DiagnosticLevel.ERROR, f"calibration failed: {error}"))
    if converged is False:
        findings.append((DiagnosticLevel.ERROR, "the last identification did not converge"))
    if last_calibration_ns is None and not error:
        findings.append((DiagnosticLevel.WARN, f"waiting for samples ({samples} of {min_samples})"))
    if condition_number is not None and not condition_number <= limits.condition_warn:
        findings.append(
            (DiagnosticLevel.WARN, f"condition number {condition_number:.3g} > {limits.condition_warn:.3g}")
        )
    if residual_rms_m is not None and not residual_rms_m <= limits.residual_rms_warn_m:
        findings.append(
            (
                DiagnosticLevel.WARN,
                f"residual RMS {residual_rms_m * 1e6:.1f} um > {limits.residual_rms_warn_m * 1e6:.1f} um",
            )
        )
    level, message = _worst(findings)
    values = (
        ("samples", str(samples)),
        ("min_samples", str(min_samples)),
        ("condition_number", _fmt(condition_number)),
        ("residual_rms_m", _fmt(residual_rms_m)),
        ("lambda", _fmt(lambda_)),
        ("converged", "n/a" if converged is None else str(converged).lower()),
        ("time_since_last_calibration_s", _fmt(_age_s(now_ns, last_calibration_ns))),
    )
    return DiagnosticStatus(name, hardware_id, level, message, values)


def uncertainty_status(
    *,
    name: str,
    hardware_id: str,
    now_ns: int,
    state: str,
    samples: int,
    trials: int | None,
    converged: bool | None,
    max_standard_uncertainty_m: float | None,
    last_evaluation_ns: int | None,
    last_evaluation_s: float | None,
    error: str | None = None,
    trust_note: str = "",
) -> DiagnosticStatus:
    """Status of the Monte Carlo evaluation.

    Parameters
    ----------
    state : str
        ``idle``, ``waiting_for_samples``, ``running``, ``done`` or ``failed``.
    samples : int
        Samples held.
    trials : int or None
        Trials of the last finished evaluation.
    converged : bool or None
        Monte Carlo convergence of the last finished evaluation (True for a fixed number
        of trials, the JCGM 101 7.9 verdict for the adaptive procedure).
    max_standard_uncertainty_m : float or None [m]
        Largest per-axis standard uncertainty over the test configurations.
    last_evaluation_ns : int or None [ns]
        When the last evaluation finished.
    last_evaluation_s : float or None [s]
        How long it took (sample to published result, the latency).
    error : str, optional
        Why the last evaluation failed.
    trust_note : str, optional
        ``ModelAdequacy.trust_note`` of the last evaluation: non-empty when the campaign is
        too small for a trustworthy statement (WARN, and ``trustworthy`` false).
    """
    findings: list[tuple[DiagnosticLevel, str]] = []
    if state == "failed" or error:
        findings.append((DiagnosticLevel.ERROR, f"evaluation failed: {error or 'see the log'}"))
    if converged is False:
        findings.append((DiagnosticLevel.WARN, "the adaptive Monte Carlo did not converge (trial cap reached)"))
    if trust_note:
        findings.append((DiagnosticLevel.WARN, trust_note))
    if last_evaluation_ns is None and not findings:
        findings.append((DiagnosticLevel.WARN, f"no evaluation yet ({state})"))
    level, message = _worst(findings)
    if level == DiagnosticLevel.OK and state == "running":
        message = "ok (re-evaluating)"
    values = (
        ("state", state),
        ("samples", str(samples)),
        ("trials", "n/a" if trials is None else str(trials)),
        ("monte_carlo_converged", "n/a" if converged is None else str(converged).lower()),
        ("max_standard_uncertainty_m", _fmt(max_standard_uncertainty_m)),
        ("trustworthy", "n/a" if last_evaluation_ns is None else str(not trust_note).lower()),
        ("last_evaluation_duration_s", _fmt(last_evaluation_s)),
        ("time_since_last_evaluation_s", _fmt(_age_s(now_ns, last_evaluation_ns))),
    )
    return DiagnosticStatus(name, hardware_id, level, message, values)


def verification_status(
    *,
    name: str,
    hardware_id: str,
    now_ns: int,
    calibration: str,
    last_check_ns: int | None,
    consistent: bool | None,
    summary: str = "",
    error: str | None = None,
    p_value: float | None = None,
    n_poses: int | None = None,
    tracker_move_m: float | None = None,
    tracker_turn_rad: float | None = None,
) -> DiagnosticStatus:
    """Status of the last check measurement (``verify``) of the samples held.

    Parameters
    ----------
    calibration : str
        The calibration file checked against ("" when none is set).
    last_check_ns : int or None [ns]
        When the last check (or refusal) happened; None: none yet.
    consistent : bool or None
        Its verdict (None: none yet, or refused).
    summary : str
        Its one-line verdict (:func:`~robocal_uncertainty.report.verification_report.verification_summary`).
    error : str, optional
        Why the last check was refused.
    p_value, n_poses, tracker_move_m, tracker_turn_rad : optional
        The last check's p-value, poses and tracker move [m, rad] (None: not stated).
    """
    if error:
        level, message = DiagnosticLevel.ERROR, f"verify refused: {error}"
    elif consistent is None:
        level, message = DiagnosticLevel.OK, "no check run yet (call ~/verify)"
    elif consistent:
        level, message = DiagnosticLevel.OK, summary or "consistent"
    else:
        level, message = DiagnosticLevel.WARN, summary or "drifted"
    values = (
        ("calibration", calibration or "n/a"),
        ("verdict", "n/a" if consistent is None else ("consistent" if consistent else "drifted")),
        ("p_value", _fmt(p_value)),
        ("check_poses", "n/a" if n_poses is None else str(n_poses)),
        ("tracker_move_m", _fmt(tracker_move_m)),
        ("tracker_turn_rad", _fmt(tracker_turn_rad)),
        ("time_since_last_check_s", _fmt(_age_s(now_ns, last_check_ns))),
    )
    return DiagnosticStatus(name, hardware_id, level, message, values)
