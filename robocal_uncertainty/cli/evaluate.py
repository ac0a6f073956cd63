"""``robocal-uncertainty evaluate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from robocal_uncertainty.cli._common import SOURCES_DEFAULT_HELP, campaign_and_robot, default_sources, read_test_joints
from robocal_uncertainty.cli._evaluation import evaluate_and_report
from robocal_uncertainty.cli._options import (
    add_campaign_args,
    add_dask_arg,
    add_force_arg,
    add_source_args,
    add_test_joint_args,
    add_uncertainty_args,
)
from robocal_uncertainty.uncertainty.sources import sources_help


def register(sub: Any) -> None:
    """Add the ``evaluate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("evaluate", help="Monte Carlo uncertainty of the calibrated tool position")
    add_campaign_args(p)
    add_test_joint_args(p)
    p.add_argument(
        "--sources",
        default=None,
        help=f"comma list of {sources_help()} ({SOURCES_DEFAULT_HELP})",
    )
    add_source_args(p, "session")
    p.add_argument(
        "--field-correction",
        action="store_true",
        help="add the model-error field's conditional mean given the calibration residuals (kriging) to every test "
        "position, with the kriging covariance in the statement (as fk and map do); helps near the calibration "
        "poses of a dense campaign, fades far from them, holds in this session only; a URDF cannot carry it",
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    add_force_arg(p, "an earlier report in --out")
    add_uncertainty_args(p, trials_default="auto")
    add_dask_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    campaign, model = campaign_and_robot(args)
    test_q = read_test_joints(args, model)
    from robocal_uncertainty.uncertainty import parse_sources
    from robocal_uncertainty.uncertainty.sources.registry import sources_given_options

    sources = parse_sources(default_sources(args.sources, campaign))
    given = sources_given_options("session", vars(args))
    sources = (*sources, *(name for name in given if name not in sources))
    evaluate_and_report(
        model,
        campaign,
        test_q,
        sources=sources,
        args=args,
        out_dir=Path(args.out),
        label="evaluate",
    )
    return 0
