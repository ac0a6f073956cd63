"""``robocal-uncertainty simulate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from robocal_uncertainty.cli._common import count, load_robot
from robocal_uncertainty.cli._options import add_force_arg, add_noise_args, encoder_noise


def register(sub: Any) -> None:
    """Add the ``simulate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("simulate", help="write a simulated campaign MCAP (truth in a sidecar .truth.json)")
    p.add_argument("--robot", default="paper_arm", help="robot YAML file or shipped model name (default %(default)s)")
    p.add_argument("--out", required=True, help="campaign .mcap to write; the truth goes to the same name .truth.json")
    p.add_argument("--poses", type=int, default=53, help="number of measured poses (default %(default)s)")
    p.add_argument(
        "--frame",
        choices=("base", "tracker"),
        default="base",
        help="points in the robot base frame or in a tracker frame with an unknown base (default %(default)s)",
    )
    add_noise_args(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated robot, poses and noise (default 0)")
    g = p.add_argument_group(
        "sessions",
        "several measurement sessions of one robot: OUT.session1.mcap, OUT.session2.mcap, ... (tracker frame), each "
        "with its truth; every session places the tracker anew, later ones also remount the probe, drift the joint "
        "offsets and change the temperature",
    )
    g.add_argument("--sessions", type=int, default=None, help="number of sessions (default: one campaign)")
    g.add_argument("--session-poses", type=int, nargs="+", help="poses of each session (default --poses for all)")
    g.add_argument(
        "--tool-remount-um", type=float, default=50.0, help="probe remount std per axis, um (default %(default)s)"
    )
    g.add_argument(
        "--joint-drift-deg",
        type=float,
        default=0.002,
        help="joint-offset drift std per joint and session, deg (default %(default)s)",
    )
    g.add_argument(
        "--temperature-k",
        type=float,
        default=2.0,
        help="temperature std between sessions, K; links scale by 23e-6/K (default %(default)s)",
    )
    r = p.add_argument_group(
        "raw recording",
        "with --raw, OUT is a raw recording instead of a campaign of static poses: joint states and tracker "
        "points streamed while the arm moves from pose to pose and dwells at each (stamp jitter, latency and "
        "beam dropouts included), what `replay` and the collector node take; the static windows are stored "
        "in the file",
    )
    r.add_argument("--raw", action="store_true", help="write a raw recording (see the group's description)")
    r.add_argument("--joint-rate-hz", type=float, default=125.0, help="joint state rate, Hz (default %(default)s)")
    r.add_argument("--tracker-rate-hz", type=float, default=500.0, help="tracker point rate, Hz (default %(default)s)")
    r.add_argument("--dwell-s", type=float, default=2.0, help="time at each pose, s (default %(default)s)")
    r.add_argument("--move-s", type=float, default=3.0, help="time of each move, s (default %(default)s)")
    add_force_arg(p, "the campaign and truth files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import simulate
    from robocal_uncertainty.core import SimulationSettings, TrackerNoise
    from robocal_uncertainty.errors import ConfigError

    model = load_robot(args.robot)
    settings = SimulationSettings(
        n_poses=args.poses,
        frame=args.frame,
        tracker_noise=TrackerNoise(a=args.tracker_noise_um * 1e-6, b=args.tracker_noise_um_per_m * 1e-6),
        encoder_noise=encoder_noise(args),
    )
    if args.sessions is not None or args.session_poses is not None:
        if args.raw:
            msg = "--raw writes one recording: it does not combine with --sessions or --session-poses"
            raise ConfigError(msg)
        return _run_sessions(args, model, settings)
    if args.raw:
        return _run_raw(args, model, settings)
    files = simulate(model, settings, args.out, seed=args.seed, overwrite=args.force)
    print(
        f"wrote {files.campaign_path} ({count(files.simulation.campaign.n_poses, 'pose')}, "
        f"points in the {args.frame} frame) "
        f"and truth {files.truth_path}"
    )
    return 0


def _run_raw(args: argparse.Namespace, model: Any, settings: Any) -> int:
    from robocal_uncertainty.app.simulation import simulate_raw_recording_file
    from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings

    recording = RawBagSettings(
        joint_rate_hz=args.joint_rate_hz, tracker_rate_hz=args.tracker_rate_hz, dwell_s=args.dwell_s, move_s=args.move_s
    )
    files = simulate_raw_recording_file(model, settings, recording, args.out, seed=args.seed, overwrite=args.force)
    raw = files.recording
    print(
        f"wrote raw recording {files.recording_path} ({count(len(raw.windows), 'pose')}, points in the {args.frame} "
        f"frame; {raw.joint_count} joint states at {args.joint_rate_hz:g} Hz on {recording.joint_topic}, "
        f"{raw.point_count} tracker points at {args.tracker_rate_hz:g} Hz on {raw.tracker_topic}) "
        f"and truth {files.truth_path}"
    )
    return 0


def _run_sessions(args: argparse.Namespace, model: Any, settings: Any) -> int:
    from robocal_uncertainty.app.simulation import simulate_sessions_files
    from robocal_uncertainty.core.simulation import SessionSimulationSettings
    from robocal_uncertainty.errors import ConfigError

    n = args.sessions if args.sessions is not None else len(args.session_poses)
    poses = tuple(args.session_poses) if args.session_poses else args.poses
    if args.session_poses and len(args.session_poses) != n:
        msg = f"--session-poses gives {len(args.session_poses)} counts for {n} sessions"
        raise ConfigError(msg)
    for option, value in (
        ("--tool-remount-um", args.tool_remount_um),
        ("--joint-drift-deg", args.joint_drift_deg),
        ("--temperature-k", args.temperature_k),
    ):
        if not (np.isfinite(value) and value >= 0):
            msg = f"{option} must be a finite number >= 0, got {value:g}"
            raise ConfigError(msg)
    session_settings = SessionSimulationSettings(
        n_sessions=n,
        n_poses=poses,
        base=settings,
        tool_remount_std=args.tool_remount_um * 1e-6,
        joint_offset_std=float(np.radians(args.joint_drift_deg)),
        temperature_std=args.temperature_k,
    )
    files = simulate_sessions_files(model, session_settings, args.out, seed=args.seed, overwrite=args.force)
    for k, (path, truth, change) in enumerate(
        zip(files.campaign_paths, files.truth_paths, files.simulation.changes), start=1
    ):
        campaign = files.simulation.sessions[k - 1].campaign
        xyz = np.asarray(change.tracker_xyz) * 1e3
        print(
            f"wrote session {k}: {path} ({count(campaign.n_poses, 'pose')}, tracker at "
            f"({xyz[0]:.0f}, {xyz[1]:.0f}, {xyz[2]:.0f}) mm, temperature {change.temperature_delta:+.2f} K) "
            f"and truth {truth}"
        )
    return 0
