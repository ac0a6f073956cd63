"""``robocal-uncertainty fk``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from robocal_uncertainty.cli._common import joint_configurations, load_robot
from robocal_uncertainty.cli._options import add_force_arg, add_urdf_chain_args


def register(sub: Any) -> None:
    """Add the ``fk`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("fk", help="tool positions of the nominal or calibrated model")
    p.add_argument(
        "--robot", required=True, help="robot YAML file, shipped model name (paper_arm, ur10) or URDF file (.urdf)"
    )
    add_urdf_chain_args(p)
    p.add_argument("--calibration", help="calibration JSON from 'calibrate --json' (default: the nominal model)")
    p.add_argument("--joints", nargs="+", help="joint values, n_joints per configuration")
    p.add_argument("--joints-file", help="CSV/whitespace file, one configuration per row")
    p.add_argument("--degrees", action="store_true", help="joint values are in degrees (default radians)")
    p.add_argument(
        "--frame",
        choices=("measurement", "base"),
        help="frame of the printed points: the measurement (tracker) frame when the calibration identified the "
        "base (default then), else the robot base frame",
    )
    p.add_argument("--json", help="also write both frames' points to this JSON file (SI units)")
    add_force_arg(p, "the --json file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import tool_points
    from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration

    model = load_robot(args.robot, base_link=args.base_link, tip_link=args.tip_link, tool_point=args.tool_point)
    if args.calibration:
        model = apply_calibration(model, read_calibration(args.calibration), where=f"calibration {args.calibration}")
    q = joint_configurations(
        model, args.joints_file, args.joints, degrees=args.degrees, flag="--joints", noun="configuration"
    )
    points = tool_points(model, q, calibrated=bool(args.calibration), frame=args.frame)
    print(
        f"# tool point of the {points.model} {model.name} model in frame {points.frame_id} ({points.frame} frame), mm"
    )
    print(f"# x_{points.frame_id} y_{points.frame_id} z_{points.frame_id}")
    for row in points.points:
        print(" ".join(f"{v * 1e3:.6f}" for v in row))
    if args.json:
        Path(args.json).write_text(json.dumps(points.to_dict(), indent=2) + "\n", encoding="utf-8")
    return 0
