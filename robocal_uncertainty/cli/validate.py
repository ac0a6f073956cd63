"""``robocal-uncertainty validate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

from robocal_uncertainty.app.campaign_checks import check_campaign_joints
from robocal_uncertainty.cli._common import (
    SOURCES_DEFAULT_HELP,
    campaign_and_robot,
    default_sources,
    parse_sources_arg,
    read_campaign_checked,
)
from robocal_uncertainty.cli._evaluation import evaluation_options
from robocal_uncertainty.cli._options import add_campaign_args, add_force_arg, add_uncertainty_args
from robocal_uncertainty.uncertainty.sources import sources_help


def register(sub: Any) -> None:
    """Add the ``validate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "validate",
        help="prove the uncertainty statement: calibrate on some poses, check the coverage of held-out measurements",
    )
    add_campaign_args(p)
    split = p.add_argument_group("what is held out (default: --holdout-fraction 0.25)")
    split.add_argument("--train-poses", type=int, help="calibrate on this many random poses, hold out the rest")
    split.add_argument("--holdout-fraction", type=float, help="fraction of the poses held out at random")
    split.add_argument("--k-folds", type=int, help="k-fold cross-validation: every pose held out once")
    split.add_argument("--validation-campaign", help="a second campaign of the same tracker set-up, held out whole")
    p.add_argument(
        "--sources",
        default=None,
        help=f"sources of the statement under test: {sources_help()} ({SOURCES_DEFAULT_HELP})",
    )
    p.add_argument(
        "--field-correction",
        action="store_true",
        help="check the statement with the model-error field's correction (kriging) from the training poses, as "
        "evaluate --field-correction states it: the held-out RMS with and without it is printed",
    )
    p.add_argument("--out", default="robocal_validation", help="report directory (default %(default)s)")
    add_force_arg(p, "an earlier report in --out")
    add_uncertainty_args(p, trials_default="5000")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import validate
    from robocal_uncertainty.app.validation import validate_with_field_correction
    from robocal_uncertainty.report.validation_report import (
        format_field_correction,
        format_validation,
        write_validation_report,
    )

    campaign, model = campaign_and_robot(args)
    options = evaluation_options(args, parse_sources_arg(default_sources(args.sources, campaign)), None)
    validation_campaign = None
    if args.validation_campaign:
        validation_campaign = read_campaign_checked(args, args.validation_campaign)
        check_campaign_joints(model, validation_campaign, args.validation_campaign)
    split = {
        "train_poses": args.train_poses,
        "holdout_fraction": args.holdout_fraction,
        "k_folds": args.k_folds,
        "validation_campaign": validation_campaign,
        "workers": args.workers,
        "progress": print,
    }
    extra: dict[str, object] = {}
    if args.field_correction:
        validation, check = validate_with_field_correction(model, campaign, options, **split)
        extra["field_correction"] = check.to_dict()
    else:
        validation = validate(model, campaign, options, **split)
    print()
    print(format_validation(validation))
    if args.field_correction:
        print(format_field_correction(check.to_dict()))
    from robocal_uncertainty.app.output_paths import clear_earlier_report

    clear_earlier_report(args.out)
    out = write_validation_report(
        args.out,
        validation,
        extra={"campaign": str(args.campaign), "robot": str(args.robot), "trials": int(options.trials), **extra},
    )
    print(f"report written to {out}")
    return 0
