"""``robocal-uncertainty verify``: its options (:func:`register`) and its work and printing (:func:`run`).

Exit status: 0 consistent, 3 drifted (so a shop-floor script can branch on it), 1 error.
"""

from __future__ import annotations

import argparse
from typing import Any

from robocal_uncertainty.app.campaign_checks import check_campaign_joints
from robocal_uncertainty.cli._common import load_robot, read_campaign_checked
from robocal_uncertainty.cli._options import add_force_arg, add_noise_args, add_urdf_chain_args, given_noise

DRIFTED_EXIT_STATUS = 3
"""Exit status of a check that says drifted."""


def register(sub: Any) -> None:
    """Add the ``verify`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "verify",
        help="check measurement: re-register a new session and test the robot against its calibration",
        description="Re-register the measurement frame of a new session (and the tool point with --retool) on a "
        "short check campaign (5-20 poses spread over the workspace) and test whether the robot still agrees "
        "with its calibration within the stated uncertainty. Exit status 0: consistent; 3: drifted; 1: error.",
    )
    p.add_argument("calibration", help="calibration JSON written by calibrate --json")
    p.add_argument("check_campaign", help="check campaign (.mcap or rosbag2 directory) of the new session")
    p.add_argument("--robot", required=True, help="robot YAML file or shipped model name (paper_arm, ur10)")
    add_urdf_chain_args(p)
    p.add_argument("--retool", action="store_true", help="the probe was remounted: re-register the tool point too")
    p.add_argument(
        "--significance",
        type=float,
        default=0.05,
        help="test level: the false-alarm rate when nothing changed (default %(default)s)",
    )
    p.add_argument(
        "--null-trials",
        type=int,
        default=20000,
        help="Monte Carlo draws of the test statistic when nothing changed (default %(default)s)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of those draws (default 0)")
    add_noise_args(p, unset_means="the calibration's")  # the new session's instruments
    p.add_argument(
        "--effects",
        action="store_true",
        help="also estimate what changed since the calibration (joint offsets, length scale) on the check",
    )
    p.add_argument("--out", help="report directory: verify.json, verify.md, verify.png (default: print only)")
    add_force_arg(p, "the report directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app.output_paths import check_report_directory
    from robocal_uncertainty.app.verification import load_session_calibration, verify
    from robocal_uncertainty.errors import ConfigError
    from robocal_uncertainty.report.verification_report import verification_lines, write_verification_report

    if not 0.0 < args.significance < 1.0:
        msg = f"--significance is a probability in (0, 1), got {args.significance:g}"
        raise ConfigError(msg)
    if args.null_trials < 100:
        msg = f"--null-trials must be at least 100, got {args.null_trials}"
        raise ConfigError(msg)
    if args.out:
        check_report_directory(args.out, force=args.force, option="--out")
    model = load_robot(args.robot, base_link=args.base_link, tip_link=args.tip_link, tool_point=args.tool_point)
    _, state, _ = load_session_calibration(model, args.calibration)  # a bad file is named before the campaign
    check = read_campaign_checked(args, args.check_campaign)
    check_campaign_joints(model, check, args.check_campaign)
    tracker, encoder = given_noise(args, state.tracker_noise, state.encoder_noise)
    run_ = verify(
        model,
        args.calibration,
        check,
        check_name=str(args.check_campaign),
        retool=args.retool,
        significance=args.significance,
        tracker_noise=tracker,
        encoder_noise=encoder,
        null_trials=args.null_trials,
        seed=args.seed,
        effects=args.effects,
    )
    result = run_.verification
    for line in verification_lines(result, scope=run_.scope_text):
        print(line)
    if args.out:
        for path in write_verification_report(
            result,
            args.out,
            calibration=str(args.calibration),
            check_campaign=str(args.check_campaign),
            robot=model.name,
            scope=run_.scope,
        ):
            print(f"wrote {path}")
    return 0 if result.consistent else DRIFTED_EXIT_STATUS
