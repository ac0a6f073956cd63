"""``robocal-uncertainty compensate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocal_uncertainty.cli._options import add_force_arg, add_noise_args, add_urdf_chain_args

if TYPE_CHECKING:
    from robocal_uncertainty.app.compensation import Compensation
    from robocal_uncertainty.core.campaign import Campaign
    from robocal_uncertainty.uncertainty import EvaluationSettings


def register(sub: Any) -> None:
    """Add the ``compensate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "compensate",
        help="joints that reach Cartesian targets under the calibrated model, with the reached position's uncertainty",
    )
    p.add_argument("calibration", help="calibration JSON from 'calibrate --json'")
    p.add_argument(
        "targets",
        help="targets: CSV with units in the header (x_mm,y_mm,z_mm[,rx_deg,ry_deg,rz_deg | qx,qy,qz,qw]) or YAML",
    )
    p.add_argument("--robot", required=True, help="the robot the calibration was identified on (YAML, name or URDF)")
    add_urdf_chain_args(p)
    p.add_argument(
        "--frame",
        choices=("measurement", "base"),
        help="frame of the targets: the measurement (tracker) frame when the calibration identified the base "
        "(default then), else the robot base frame",
    )
    p.add_argument(
        "--orientation-convention",
        help="Euler convention of rx, ry, rz in the targets: intrinsic_xyz, extrinsic_xyz (ROS/UR roll-pitch-yaw), "
        "intrinsic_zyx, intrinsic_zyz (required when the targets give Euler angles)",
    )
    p.add_argument("--seed-joints", nargs="+", help="joints to start from and whose branch to keep: one configuration")
    p.add_argument(
        "--seed-joints-file",
        help="CSV/whitespace file: one seed configuration per target (e.g. the controller's own solutions)",
    )
    p.add_argument("--degrees", action="store_true", help="seed joint values are in degrees (default radians)")
    p.add_argument(
        "--branch",
        help="UR arms, pose targets, no seeds: the branch of the analytic nominal solution, e.g. "
        "shoulder=+1,elbow=+1,wrist=-1 (signs of the shoulder term, sin(elbow_joint), sin(wrist_2_joint); "
        "default: the branch of the campaign pose nearest to each target)",
    )
    p.add_argument(
        "--campaign",
        help="the calibration's campaign (default: the one its session record names, if present): the Monte Carlo "
        "of the reached positions' uncertainty, and the seeds' start without --seed-joints",
    )
    p.add_argument("--no-uncertainty", action="store_true", help="joints only: no Monte Carlo")
    p.add_argument(
        "--max-joint-change",
        type=float,
        default=0.05,
        help="largest correction of any joint, rad (default %(default)g)",
    )
    p.add_argument(
        "--condition-limit",
        type=float,
        default=1e3,
        help="refuse targets whose task Jacobian condition number exceeds this (default %(default)g)",
    )
    p.add_argument("--trials", type=int, default=5000, help="Monte Carlo trials (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="root seed of the random streams (default %(default)s)")
    p.add_argument("--coverage", type=float, default=0.95, help="coverage probability p (default %(default)s)")
    p.add_argument("--sources", default=None, help="uncertainty sources (default: the validated set, as evaluate)")
    add_noise_args(p)
    p.add_argument("--workers", type=int, default=1, help="worker processes (never changes the result)")
    p.add_argument("--csv", dest="csv_out", help="write the joint targets (CSV, units in the header)")
    p.add_argument("--json", help="write joints, errors, refusals, uncertainty and settings (JSON)")
    p.add_argument("--urscript", help="write a URScript movej program (UR robots)")
    p.add_argument("--acceleration", type=float, default=1.4, help="URScript movej a, rad/s^2 (default %(default)g)")
    p.add_argument("--velocity", type=float, default=1.05, help="URScript movej v, rad/s (default %(default)g)")
    add_force_arg(p, "the --csv, --json and --urscript files")
    p.set_defaults(func=run)


def _parse_branch(text: str) -> dict[str, int]:
    from robocal_uncertainty.errors import ConfigError

    out: dict[str, int] = {}
    for item in text.split(","):
        name, _, sign = item.partition("=")
        if sign.strip() not in ("+1", "1", "-1"):
            msg = f"--branch {text!r}: expected NAME=+1 or NAME=-1 items (shoulder, elbow, wrist), got {item!r}"
            raise ConfigError(msg)
        out[name.strip()] = -1 if sign.strip() == "-1" else 1
    return out


def _campaign_path(args: argparse.Namespace, data: dict[str, Any]) -> str | None:
    if args.campaign:
        return str(args.campaign)
    session = data.get("session")
    named = session.get("campaign") if isinstance(session, dict) else None
    return str(named) if isinstance(named, str) and Path(named).exists() else None


def _check_numbers_and_outputs(args: argparse.Namespace) -> None:
    """Refuse non-positive IK limits and output files that exist (without --force), are inputs or repeat."""
    import numpy as np

    from robocal_uncertainty.app.output_paths import check_output_file
    from robocal_uncertainty.errors import ConfigError

    for value, option in ((args.max_joint_change, "--max-joint-change"), (args.condition_limit, "--condition-limit")):
        if not (np.isfinite(value) and value > 0):
            msg = f"{option} must be a finite number > 0, got {value:g}"
            raise ConfigError(msg)
    outputs = [(getattr(args, k), o) for k, o in (("csv_out", "--csv"), ("json", "--json"), ("urscript", "--urscript"))]
    inputs = [args.calibration, args.targets, args.campaign, args.seed_joints_file]
    written: list[Path] = []
    for path, option in outputs:
        if not path:
            continue
        check_output_file(Path(path), force=bool(args.force), option=option)
        if any(i and Path(i).exists() and Path(i).resolve() == Path(path).resolve() for i in inputs):
            msg = f"{option} {path} is one of the command's inputs"
            raise ConfigError(msg)
        if Path(path).resolve() in written:
            msg = f"{option} {path} is named by another output option too"
            raise ConfigError(msg)
        written.append(Path(path).resolve())


def _evaluation_settings(args: argparse.Namespace, campaign: Campaign | None) -> EvaluationSettings:
    """The Monte Carlo settings of the statement (needs the calibration's campaign)."""
    from robocal_uncertainty.cli._common import default_sources, parse_sources_arg
    from robocal_uncertainty.cli._options import encoder_noise
    from robocal_uncertainty.core import TrackerNoise
    from robocal_uncertainty.errors import ConfigError
    from robocal_uncertainty.uncertainty import EvaluationSettings, UncertaintySettings

    if campaign is None:
        msg = (
            "the uncertainty of the reached positions needs the calibration's campaign: give --campaign "
            "(or --no-uncertainty)"
        )
        raise ConfigError(msg)
    sources = parse_sources_arg(default_sources(args.sources, campaign))
    return EvaluationSettings(
        uncertainty=UncertaintySettings(
            sources=sources,
            tracker_noise=TrackerNoise(a=args.tracker_noise_um * 1e-6, b=args.tracker_noise_um_per_m * 1e-6),
            encoder_noise=encoder_noise(args),
        ),
        trials=args.trials,
        seed=args.seed,
        coverage=args.coverage,
    )


def _write_outputs(args: argparse.Namespace, result: Compensation) -> None:
    """The CSV, JSON and URScript files asked for."""
    if args.csv_out:
        Path(args.csv_out).write_text(result.csv_text(), encoding="utf-8")
        print(f"wrote {args.csv_out}")
    if args.json:
        Path(args.json).write_text(json.dumps(result.to_dict(), indent=2) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    if args.urscript:
        text = result.urscript_text(acceleration=args.acceleration, velocity=args.velocity)
        Path(args.urscript).write_text(text, encoding="utf-8")
        print(f"wrote {args.urscript}")


def run(args: argparse.Namespace) -> int:

    from robocal_uncertainty.app.campaign_checks import check_campaign_joints
    from robocal_uncertainty.app.compensation import compensate
    from robocal_uncertainty.cli._common import joint_configurations, load_robot, read_campaign_checked
    from robocal_uncertainty.core.calibration_file import read_calibration
    from robocal_uncertainty.core.inverse_kinematics import IkSettings
    from robocal_uncertainty.errors import ConfigError
    from robocal_uncertainty.importers.targets import read_targets

    _check_numbers_and_outputs(args)
    data = read_calibration(args.calibration)
    model = load_robot(args.robot, base_link=args.base_link, tip_link=args.tip_link, tool_point=args.tool_point)
    targets = read_targets(args.targets, orientation_convention=args.orientation_convention)
    seeds = None
    if args.seed_joints or args.seed_joints_file:
        seeds = joint_configurations(
            model, args.seed_joints_file, args.seed_joints, degrees=args.degrees, flag="--seed-joints", noun="seed"
        )
    campaign = None
    path = _campaign_path(args, data)
    if path is not None and (seeds is None or not args.no_uncertainty):
        campaign = read_campaign_checked(args, path)
        check_campaign_joints(model, campaign, path)
    options = None if args.no_uncertainty else _evaluation_settings(args, campaign)
    settings = IkSettings(max_joint_change_rad=args.max_joint_change, condition_limit=args.condition_limit)
    branch = _parse_branch(args.branch) if args.branch else None
    if branch is not None and seeds is not None:
        raise ConfigError("--branch chooses the nominal solution without seeds: give it or --seed-joints, not both")
    result = compensate(
        model,
        data,
        targets,
        frame=args.frame,
        seeds=seeds,
        campaign=campaign,
        options=options,
        settings=settings,
        branch=branch,
        where=f"calibration {args.calibration}",
        workers=args.workers,
    )
    _print(result)
    _write_outputs(args, result)
    return 0


def _print(result: Any) -> None:
    import numpy as np

    sol = result.solution
    print(
        f"# {result.targets.n} targets of {result.targets.source} in frame {result.frame_id} ({result.frame} frame); "
        f"seeds: {result.seed_source}; {int(result.accepted.sum())} compensated"
    )
    unc = result.uncertainty
    if unc is not None:
        print(
            f"# reached position: Monte Carlo of evaluate, {unc.n_trials} trials, seed {unc.seed}, sources "
            f"{','.join(unc.settings.sources)}, {100 * unc.coverage_probability:g} % intervals; "
            f"campaign re-identified to {result.reproduction_m * 1e3:.2g} mm of the calibration"
        )
    k = 0
    for i in range(result.targets.n):
        line = f"target {i + 1}: {result.status[i]}"
        if result.accepted[i]:
            line = (
                f"target {i + 1}: ok, FK error {sol.position_error_m[i] * 1e3:.2g} mm, largest joint correction "
                f"{np.degrees(sol.joint_change[i]):.4g} deg"
            )
            if unc is not None:
                pose = unc.poses[k]
                k += 1
                u = ", ".join(f"{a.standard_uncertainty * 1e3:.3f}" for a in pose.axes)
                big_u = ", ".join(f"{a.expanded_uncertainty * 1e3:.3f}" for a in pose.axes)
                line += f"; u = ({u}) mm, U = ({big_u}) mm"
        print(line)
    if unc is not None:
        for warning in unc.warnings:
            print(f"warning: {warning}")
