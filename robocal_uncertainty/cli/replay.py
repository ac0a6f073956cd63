"""``robocal-uncertainty replay``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from robocal_uncertainty.cli._common import (
    Progress,
    count,
    load_robot,
    parse_sources_arg,
    parse_window,
    read_test_joints,
)
from robocal_uncertainty.cli._evaluation import evaluation_options, print_evaluation
from robocal_uncertainty.cli._options import (
    add_base_unknown_arg,
    add_force_arg,
    add_test_joint_args,
    add_uncertainty_args,
    add_urdf_chain_args,
)
from robocal_uncertainty.montecarlo.executor import RunContext
from robocal_uncertainty.uncertainty.sources import default_sources as default_source_names
from robocal_uncertainty.uncertainty.sources import sources_help


def register(sub: Any) -> None:
    """Add the ``replay`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "replay", help="replay a raw bag: detect static poses, calibrate, evaluate (same report as evaluate)"
    )
    p.add_argument("bag", help="raw recording: .mcap file or rosbag2 directory")
    p.add_argument(
        "--robot", required=True, help="robot YAML file, shipped model name (paper_arm, ur10) or URDF file (.urdf)"
    )
    add_urdf_chain_args(p)
    add_base_unknown_arg(p)
    add_test_joint_args(p)
    p.add_argument(
        "--sources",
        default=None,
        help=f"comma list of {sources_help()} (default tracker,encoder,residual: the validated set; and "
        "tracker_orientation with --tracker-pose-topic)",
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    add_force_arg(p, "an earlier report in --out and the --campaign-out file")
    p.add_argument("--joint-topic", default="/joint_states", help="sensor_msgs/JointState topic (default %(default)s)")
    p.add_argument(
        "--point-topic", default="/tracker/point", help="geometry_msgs/PointStamped topic (default %(default)s)"
    )
    p.add_argument(
        "--tracker-pose-topic",
        help="6-DOF tracker: geometry_msgs/PoseStamped (or PoseWithCovarianceStamped) topic read instead of "
        "--point-topic; the campaign then holds orientations (e.g. /tracker/pose)",
    )
    p.add_argument("--tracker-frame", help="frame_id of valid tracker points (default: the most frequent)")
    p.add_argument(
        "--window-s",
        default="auto",
        help="static window length, s, or auto: 0.5 s, shortened to half the typical still interval of the "
        "joints when the recording's dwells are shorter (default %(default)s)",
    )
    p.add_argument(
        "--joint-motion-threshold-rad",
        type=float,
        default=5e-4,
        help="max joint motion in a static window, rad (default %(default)s)",
    )
    p.add_argument(
        "--tracker-scatter-threshold-m",
        type=float,
        default=1e-4,
        help="max tracker scatter in a static window, m (default %(default)s)",
    )
    p.add_argument(
        "--orientation-scatter-threshold-rad",
        type=float,
        default=2e-3,
        help="6-DOF tracker: max range of any rotation-matrix entry in a static window, rad (default %(default)s)",
    )
    p.add_argument(
        "--min-points", type=int, default=10, help="min tracker points averaged per static pose (default %(default)s)"
    )
    p.add_argument("--campaign-out", help="also write the collected campaign MCAP here")
    add_uncertainty_args(p, trials_default="auto")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import replay
    from robocal_uncertainty.pipeline import CollectorSettings

    model = load_robot(
        args.robot,
        base_known=False if args.base_unknown else None,
        base_link=args.base_link,
        tip_link=args.tip_link,
        tool_point=args.tool_point,
    )
    sources = args.sources
    if sources is None:
        # A tracker pose topic means a 6-DOF campaign: its orientation noise is an input too.
        sources = ",".join(default_source_names(bool(args.tracker_pose_topic)))
    options = evaluation_options(args, parse_sources_arg(sources), read_test_joints(args, model))
    window = parse_window(args.window_s)
    settings = CollectorSettings(
        window_s=window if window is not None else CollectorSettings().window_s,
        joint_motion_threshold=args.joint_motion_threshold_rad,
        tracker_scatter_threshold=args.tracker_scatter_threshold_m,
        min_points=args.min_points,
        orientation_scatter_threshold=args.orientation_scatter_threshold_rad,
    )
    if args.campaign_out and args.force:
        Path(args.campaign_out).unlink(missing_ok=True)  # --force: replay writes a new campaign

    def log(cause: str, message: str) -> None:
        print(f"replay: dropped ({cause}): {message}", file=sys.stderr)

    bars = Progress(not args.no_progress, "replay", max_trials=args.max_trials)
    try:
        replayed = replay(
            args.bag,
            model,
            options,
            joint_topic=args.joint_topic,
            point_topic=args.point_topic,
            tracker_pose_topic=args.tracker_pose_topic,
            tracker_frame_id=args.tracker_frame,
            collector=settings,
            campaign_path=args.campaign_out,
            log=log,
            auto_window=window is None,
            run=RunContext(workers=args.workers, progress=bars.main),
            phase_progress=bars.phase,
        )
    finally:
        bars.close()
    result = replayed.replay
    dropped = ", ".join(f"{k}: {v}" for k, v in sorted(result.dropped.items()) if v) or "none"
    used = result.collector
    how = "auto, from the joints' still intervals" if window is None else "--window-s"
    print(
        f"replay of {args.bag}: {count(len(result.samples), 'static pose')} found "
        f"(window {used.window_s:g} s, {how}); dropped messages: {dropped}"
    )
    if args.campaign_out:
        print(f"campaign written to {args.campaign_out}")
    print_evaluation(replayed.evaluation, options, model, Path(args.out), bars, args)
    return 0
