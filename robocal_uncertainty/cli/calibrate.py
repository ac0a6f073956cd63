"""``robocal-uncertainty calibrate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

from robocal_uncertainty.cli._common import campaign_and_robot, parse_lambda
from robocal_uncertainty.cli._evaluation import print_calibration
from robocal_uncertainty.cli._options import add_campaign_args, add_force_arg


def register(sub: Any) -> None:
    """Add the ``calibrate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("calibrate", help="identify the parameter errors from a campaign")
    add_campaign_args(p)
    p.add_argument(
        "--lambda",
        dest="lambda_",
        default="auto",
        help="auto (L-curve corner), gcv, or a fixed value (default %(default)s)",
    )
    p.add_argument("--json", help="also write the result to this JSON file (SI units)")
    add_force_arg(p, "the --json file")
    p.add_argument(
        "--accept-unconverged",
        action="store_true",
        help="report an identification that did not converge instead of stopping with an error",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.core import identify
    from robocal_uncertainty.core.calibration_file import write_calibration

    campaign, model = campaign_and_robot(args)
    result = identify(model, campaign, lambda_=parse_lambda(args.lambda_), accept_unconverged=args.accept_unconverged)
    print_calibration(result)
    if args.json:
        write_calibration(args.json, result, robot=str(args.robot))
        print(f"wrote {args.json}")
    return 0
