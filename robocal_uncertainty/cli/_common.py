"""What every command shares: robot and campaign reading with their checks, joint values,
option value parsers, progress bars, the library's words turned into the command line's."""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.app.campaign_checks import check_campaign_joints, refuse_raw_recording
from robocal_uncertainty.errors import ConfigError, InputError

DEFAULT_PAIRING_TOLERANCE_MS = 50.0
"""Default of ``--pairing-tolerance-ms``: a tracker point stamped up to this long before or after
its joint reading is paired with it (tracker latency of a real recording is a few ms; poses are
seconds apart)."""


def load_robot(
    name: str,
    *,
    base_known: bool | None = None,
    base_link: str | None = None,
    tip_link: str | None = None,
    tool_point: Sequence[float] | None = None,
) -> Any:
    """The model of :func:`load_robot_source`."""
    return load_robot_source(
        name, base_known=base_known, base_link=base_link, tip_link=tip_link, tool_point=tool_point
    ).model


def load_robot_source(
    name: str,
    *,
    base_known: bool | None = None,
    base_link: str | None = None,
    tip_link: str | None = None,
    tool_point: Sequence[float] | None = None,
) -> Any:
    """``--robot``: a robot YAML, a shipped model name, or a URDF (``.urdf``) with its chain ends
    and, when known, the measured point in the tip link (``--tool-point``, m); read by the
    package's one robot loader (:func:`robocal_uncertainty.core.robot_formats.load_robot_source`)."""
    from robocal_uncertainty.core import robot_formats

    chain_given = base_link is not None or tip_link is not None or tool_point is not None
    if chain_given and not robot_formats.robot_format_of(name).chain_ends:
        msg = (
            f"--base-link, --tip-link and --tool-point describe a URDF chain; --robot {name} is not a .urdf file "
            "(a robot YAML gives its tool_point)"
        )
        raise ConfigError(msg)
    return robot_formats.load_robot_source(
        name, base_link=base_link, tip_link=tip_link, tool_point=tool_point, base_known=base_known
    )


def _in_radians(q: NDArray[np.float64], degrees: bool, prismatic: Sequence[bool]) -> NDArray[np.float64]:
    """`q` [rad, or deg with `degrees`] in rad; a prismatic joint's column is in m either way."""
    if not degrees:
        return q
    linear = np.zeros(q.shape[1], dtype=bool) if not prismatic else np.asarray(prismatic, dtype=bool)
    return np.asarray(np.where(linear, q, np.radians(q)), dtype=np.float64)


def parse_joint_values(
    values: Sequence[str], n_joints: int, *, degrees: bool, what: str, prismatic: Sequence[bool] = ()
) -> NDArray[np.float64]:
    try:
        numbers = [float(v) for item in values for v in item.replace(",", " ").split()]
    except ValueError as err:
        msg = f"{what}: not a number ({err})"
        raise InputError(msg) from err
    if not numbers or len(numbers) % n_joints:
        msg = f"{what} must have {n_joints} values per configuration, got {len(numbers)}"
        raise ConfigError(msg)
    q = np.array(numbers).reshape(-1, n_joints)
    if not np.isfinite(q).all():
        msg = f"{what} contain NaN or inf"
        raise InputError(msg)
    return _in_radians(q, degrees, prismatic)


def read_joints_file(path: str, n_joints: int, *, degrees: bool, prismatic: Sequence[bool] = ()) -> NDArray[np.float64]:
    """Joint configurations from a text file: one per row, numbers separated by commas,
    semicolons or whitespace; blank lines, ``#`` comments and a header row are skipped.
    With `degrees`, the revolute joints' values are converted to rad (prismatic ones stay in m)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        msg = f"cannot read joints file {path}: not UTF-8 text"
        raise InputError(msg) from err
    except OSError as err:
        msg = f"cannot read joints file {path}: {err.strerror}"
        raise InputError(msg) from err
    rows: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        cells = line.replace(";", ",").replace(",", " ").split()
        if not cells or cells[0].startswith("#") or (not rows and cells[0][0].isalpha()):
            continue
        try:
            values = [float(v) for v in cells]
        except ValueError:
            bad = next(v for v in cells if not is_number(v))
            msg = f"joints file {path}, line {number}: {bad!r} is not a number"
            raise InputError(msg) from None
        if len(values) != n_joints:
            msg = f"joints file {path}, line {number}: {len(values)} values, the robot has {n_joints} joints"
            raise ConfigError(msg)
        if not np.isfinite(values).all():
            msg = f"joints file {path}, line {number}: NaN or inf"
            raise InputError(msg)
        rows.append(values)
    if not rows:
        msg = f"joints file {path} has no configuration (one row of {n_joints} numbers per configuration)"
        raise ConfigError(msg)
    q = np.array(rows)
    return _in_radians(q, degrees, prismatic)


def is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_trials(text: str) -> int | str:
    if text == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError as err:
        msg = f"--trials must be a positive integer or 'auto', got {text!r}"
        raise ConfigError(msg) from err
    if value <= 0:
        msg = f"--trials must be a positive integer or 'auto', got {text!r}"
        raise ConfigError(msg)
    return value


def parse_lambda(text: str) -> str | float:
    if text in ("auto", "gcv", "lcurve"):
        return text
    try:
        value = float(text)
    except ValueError as err:
        msg = f"--lambda must be 'auto', 'gcv' or a number, got {text!r}"
        raise ConfigError(msg) from err
    from robocal_uncertainty.core.identification import MAX_LAMBDA

    if not (np.isfinite(value) and 0.0 <= value <= MAX_LAMBDA):
        msg = (
            f"--lambda must be 'auto', 'gcv' or a number from 0 to {MAX_LAMBDA:g}, got {text!r} (any lambda far "
            "above 10 already holds every regularised parameter at its nominal value)"
        )
        raise ConfigError(msg)
    return value


def parse_window(text: str) -> float | None:
    """``--window-s``: a number of seconds > 0, or ``auto`` (None)."""
    if text == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        msg = f"--window-s must be 'auto' or a number of seconds > 0, got {text!r}"
        raise ConfigError(msg)
    return value


def count(n: int, noun: str) -> str:
    """``1 pose``, ``2 poses``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def seconds(value: float) -> str:
    return f"{value:.1f} s" if value >= 1 else f"{value:.2g} s"


class Progress:
    """Progress bars on stderr (tqdm) for the phases of a run: the main Monte Carlo, the
    budget, the sweeps and the report. Drawn only when `enabled` and stderr is a terminal;
    the main run's duration (first to last progress report) is measured either way."""

    def __init__(self, enabled: bool, label: str, *, max_trials: int | None = None) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.label = label
        self.max_trials = max_trials
        self.start = time.perf_counter()
        self.last = self.start
        self._bars: dict[str, Any] = {}

    def _bar(self, key: str, desc: str, total: int | None, unit: str) -> Any:
        bar = self._bars.get(key)
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, leave=False, dynamic_ncols=True)
            self._bars[key] = bar
        return bar

    def main(self, done: int, target: int | None) -> None:
        """``progress(done, target)`` of the main Monte Carlo run (target None: adaptive)."""
        self.last = time.perf_counter()
        if not self.enabled:
            return
        if target is None:
            bar = self._bar("main", f"{self.label} (adaptive JCGM 101 7.9)", None, "trial")
            bar.update(done - bar.n)
            rate = done / max(self.last - self.start, 1e-9)
            if self.max_trials:
                bar.set_postfix_str(
                    f"stops when u is stable; at most {self.max_trials} trials, "
                    f"<= {max(self.max_trials - done, 0) / rate:.0f} s more",
                    refresh=False,
                )
            return
        bar = self._bar("main", self.label, target, "trial")
        bar.total = target
        bar.update(done - bar.n)

    def phase(self, phase: str, done: int, total: int | None) -> None:
        """``phase_progress`` of :func:`robocal_uncertainty.app.evaluate` (budget, sweeps)."""
        if not self.enabled:
            return
        self.close("main")
        desc = {"budget": "budget (each source alone)", "sweeps": "sweeps (u vs lambda, vs equations)"}.get(
            phase, phase
        )
        bar = self._bar(phase, desc, total, "trial")
        bar.update(done - bar.n)
        if total is not None and done >= total:
            self.close(phase)

    def note(self, text: str) -> None:
        """A one-line status on stderr (e.g. while the report is written), when drawing."""
        if self.enabled:
            print(f"{self.label}: {text}", file=sys.stderr, flush=True)

    def close(self, key: str | None = None) -> None:
        for name in [key] if key is not None else list(self._bars):
            bar = self._bars.pop(name, None) if name is not None else None
            if bar is not None:
                bar.close()

    def elapsed(self) -> float:
        """Seconds of the main run (start to its last progress report)."""
        return max(self.last - self.start, 1e-9)


def timed_progress(enabled: bool, label: str) -> tuple[Callable[[int, int | None], None], Callable[[], float]]:
    """A progress callback (a bar on stderr when `enabled` and stderr is a terminal) and a
    function that closes the bar and returns the seconds to the last progress report."""
    bars = Progress(enabled, label)

    def finish() -> float:
        bars.close()
        return bars.elapsed()

    return bars.main, finish


def campaign_and_robot(args: argparse.Namespace) -> tuple[Any, Any]:
    """Read the campaign (its reader warnings printed as ``warning:`` lines) and the robot;
    refuse campaign joint readings outside the robot's joint limits."""
    campaign = read_campaign_checked(args, args.campaign)
    check_campaign_counts(args, campaign.n_poses)
    source = load_robot_source(
        args.robot,
        base_known=False if args.base_unknown else None,
        base_link=getattr(args, "base_link", None),
        tip_link=getattr(args, "tip_link", None),
        tool_point=getattr(args, "tool_point", None),
    )
    model = source.model
    check_campaign_joints(model, campaign, args.campaign)
    check_campaign_frame(args.robot, model, campaign, args.campaign, urdf=source.urdf if source.from_urdf else None)
    return campaign, model


def check_campaign_frame(robot: str, model: Any, campaign: Any, path: str, *, urdf: Any = None) -> None:
    """A campaign in the robot base frame must be in the model's base frame.

    Its points are taken as given in the model's base frame. When the campaign names another
    link of the same URDF (UR's ``base`` is ``base_link`` turned by 180 degrees), that is a known,
    different frame: refused, naming ``--base-link``. Another name is warned about. `urdf` is the
    URDF the model was read from (None for a model in DH form).
    """
    frame_id = str(getattr(campaign, "frame_id", "") or "")
    if campaign.frame != "base" or not frame_id or frame_id == model.base_frame_id:
        return
    if urdf is not None and frame_id in urdf.links:
        msg = (
            f"{path}: the points are in URDF link {frame_id!r}, the chain starts at {model.base_frame_id!r} "
            f"(another frame of {robot}): give --base-link {frame_id}"
        )
        raise InputError(msg)
    print(
        f"warning: {path}: the points are in frame {frame_id!r}, the robot model's base frame is "
        f"{model.base_frame_id!r}: taken as the same frame",
        file=sys.stderr,
    )


def read_campaign_checked(args: argparse.Namespace, path: str) -> Any:
    """One campaign read as every command reads it: with ``--pairing-tolerance-ms``, a raw
    recording refused, the reader's warnings printed as ``warning:`` lines."""
    import warnings

    from robocal_uncertainty.bagio import read_campaign

    tolerance_ms = getattr(args, "pairing_tolerance_ms", DEFAULT_PAIRING_TOLERANCE_MS)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        campaign = read_campaign(
            path,
            stamp_tolerance_ns=round(tolerance_ms * 1e6),
            accept_damaged=bool(getattr(args, "accept_damaged", False)),
        )
    refuse_raw_recording(path, campaign)
    stored: Any = campaign.metadata.get("warnings") or ()  # a list of strings in the file's metadata
    notes = [str(w) for w in stored]
    notes += [str(w.message) for w in caught if str(w.message) not in notes]
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    return campaign


def read_test_joints(args: argparse.Namespace, model: Any) -> NDArray[np.float64]:
    return joint_configurations(
        model,
        args.test_joints_file,
        args.test_joints,
        degrees=args.degrees,
        flag="--test-joints",
        noun="test configuration",
    )


def joint_configurations(
    model: Any, path: str | None, values: Sequence[str] | None, *, degrees: bool, flag: str, noun: str
) -> NDArray[np.float64]:
    """Configurations [rad] from ``{flag}-file`` `path` or ``{flag}`` `values`, within the joint limits."""
    from robocal_uncertainty.core import check_joint_limits

    if path and values:
        # One of them would be ignored without a word.
        msg = f"give {flag} or {flag}-file, not both ({flag}-file {path} and {len(values)} {flag} values)"
        raise ConfigError(msg)
    if path:
        q = read_joints_file(path, model.n_joints, degrees=degrees, prismatic=model.prismatic)
        what = f"{path}: {noun}"
    elif values:
        q = parse_joint_values(values, model.n_joints, degrees=degrees, what=flag, prismatic=model.prismatic)
        what = f"{flag} configuration"
    else:
        msg = f"give {flag} or {flag}-file"
        raise ConfigError(msg)
    check_joint_limits(model, q, what=what, degrees_hint=None if degrees else "did you mean --degrees?")
    return q


def check_campaign_counts(args: argparse.Namespace, n_poses: int) -> None:
    """Options bounded by the campaign's size, checked right after reading it."""
    for dest in ("min_poses", "subset_size"):
        value = getattr(args, dest, None)
        if value is not None and value > n_poses:
            msg = f"{flag(dest)} {value} is more than the campaign's {n_poses} poses"
            raise ConfigError(msg)
    train = getattr(args, "train_poses", None)
    if train is not None and train >= n_poses:
        msg = f"--train-poses {train} leaves no pose to hold out: the campaign has {n_poses} poses"
        raise ConfigError(msg)
    k_folds = getattr(args, "k_folds", None)
    if k_folds is not None and k_folds > n_poses:
        msg = f"--k-folds {k_folds} is more than the campaign's {n_poses} poses"
        raise ConfigError(msg)


def flag(dest: str) -> str:
    return "--lambda" if dest == "lambda_" else "--" + dest.replace("_", "-")


_INTERNAL_WORDS = (
    # Names the library's messages use for what the command line calls otherwise.
    (r"\(pass overwrite=True to replace it\)", "(give --force to replace it)"),
    (r"\badaptive\.max_trials\b", "--max-trials"),
    (r"or give the unit explicitly\)", "or give --unit)"),
    (r"\blambda_range\b", "--lambda-range"),
    (r"\bmin_poses\b", "--min-poses"),
    (r"\bsubset_size\b", "--subset-size"),
    (r"\bwindow_s\b", "--window-s"),
    (r"\bmin_points\b", "--min-points"),
    (r"\bjoint_motion_threshold\b", "--joint-motion-threshold-rad"),
    (r"\btracker_scatter_threshold\b", "--tracker-scatter-threshold-m"),
    (r"\bk_folds\b", "--k-folds"),
    (r"\bn_train\b", "--train-poses"),
    (r"\bthe pairing tolerance of ([0-9.e+-]+) ms\b", r"--pairing-tolerance-ms \1"),
)


def in_cli_words(message: str) -> str:
    """A library message with its argument names replaced by the command line's flags."""

    for pattern, flag in _INTERNAL_WORDS:
        message = re.sub(pattern, flag, message)
    return message


SOURCES_DEFAULT_HELP = (
    "default tracker,encoder,residual: the validated set; and tracker_orientation for a 6-DOF campaign"
)


def default_sources(given: str | None, campaign: Any) -> str:
    """``--sources`` as given, else the validated default of the campaign's measurement type
    (:func:`robocal_uncertainty.uncertainty.default_sources`)."""
    from robocal_uncertainty.uncertainty import default_sources as validated_default

    if given is not None:
        return given
    return ",".join(validated_default(bool(campaign.measurement.measures_orientation)))


def parse_sources_arg(text: str) -> tuple[str, ...]:
    from robocal_uncertainty.uncertainty import parse_sources

    return tuple(parse_sources(text))
