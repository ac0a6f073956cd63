"""``robocal-uncertainty map``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from robocal_uncertainty.cli._common import (
    SOURCES_DEFAULT_HELP,
    campaign_and_robot,
    default_sources,
    parse_lambda,
    read_joints_file,
    timed_progress,
)
from robocal_uncertainty.cli._evaluation import uncertainty_settings
from robocal_uncertainty.cli._options import (
    add_backend_arg,
    add_dask_arg,
    add_force_arg,
    add_frame_and_convergence_args,
    add_model_error_arg,
    add_noise_args,
)
from robocal_uncertainty.uncertainty.sources import sources_help


def register(sub: Any) -> None:
    """Add the ``map`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("map", help="uncertainty map over the workspace: u at many configurations, where it is weakest")
    p.add_argument("campaign", help="campaign: .mcap file or rosbag2 directory")
    p.add_argument("--robot", required=True, help="robot YAML file or shipped model name (paper_arm, ur10)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--configurations", type=int, default=1000, help="uniform random configurations (default %(default)s)"
    )
    where.add_argument(
        "--grid", type=int, nargs="+", metavar="STEPS", help="grid: values per joint (one for all, or one per joint)"
    )
    where.add_argument("--from-file", help="CSV/whitespace file, one configuration per row")
    p.add_argument("--degrees", action="store_true", help="--from-file values are in degrees (default radians)")
    p.add_argument(
        "--within-campaign", action="store_true", help="sample inside the campaign's joint span, not the joint limits"
    )
    p.add_argument("--sources", default=None, help=f"comma list of {sources_help()} ({SOURCES_DEFAULT_HELP})")
    p.add_argument("--trials", type=int, default=10_000, help="Monte Carlo trials (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="root seed of the trials and of random configurations")
    p.add_argument(
        "--coverage", type=float, default=0.95, help="coverage probability of the regions (default %(default)s)"
    )
    p.add_argument("--regions", type=int, default=0, help="first N configurations keep samples for a JCGM 102 region")
    p.add_argument("--block-size", type=int, default=1000, help="trials per random stream (default %(default)s)")
    p.add_argument("--lambda", dest="lambda_", default="auto", help="auto (L-curve corner), gcv, or a fixed value")
    add_noise_args(p)
    p.add_argument("--base-unknown", action="store_true", help="identify the base transform even if known")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (never changes the result)")
    add_backend_arg(p)
    add_dask_arg(p)
    p.add_argument("--out", default="robocal_map", help="report directory (default %(default)s)")
    add_force_arg(p, "an earlier map report in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_model_error_arg(p)
    p.add_argument(
        "--field-correction",
        action="store_true",
        help="add the model-error field's conditional mean given the calibration residuals (kriging) to every "
        "position, with its covariance in the statement; the report shows the kriging std over the field's "
        "uncorrected std per configuration (1: far from the calibration poses, where the field widens the statement)",
    )
    add_frame_and_convergence_args(p)
    p.set_defaults(func=run, lambda_range=None, min_poses=None, subset_size=None)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.montecarlo.executor import open_executor
    from robocal_uncertainty.report.map_report import weakest_region, write_map_report
    from robocal_uncertainty.uncertainty.sources import parse_sources
    from robocal_uncertainty.uncertainty.workspace_map import grid_configurations, map_workspace, sample_configurations

    campaign, model = campaign_and_robot(args)
    campaign = campaign.reorder_joints(model.joint_names)
    span = np.column_stack([campaign.joint_positions.min(axis=0), campaign.joint_positions.max(axis=0)])
    limits = span if args.within_campaign else None
    if args.from_file:
        q = read_joints_file(args.from_file, model.n_joints, degrees=args.degrees, prismatic=model.prismatic)
    elif args.grid:
        q = grid_configurations(model, args.grid[0] if len(args.grid) == 1 else args.grid, limits=limits)
    else:
        q = sample_configurations(model, args.configurations, rng=np.random.default_rng(args.seed), limits=limits)
    settings = uncertainty_settings(args, None, parse_sources(default_sources(args.sources, campaign)))
    progress, finish = timed_progress(not args.no_progress, "map")
    try:
        with open_executor(workers=args.workers, dask=args.dask) as executor:
            wmap = map_workspace(
                model,
                campaign,
                q,
                settings=settings,
                lambda_=parse_lambda(args.lambda_),
                accept_unconverged=args.accept_unconverged,
                trials=args.trials,
                seed=args.seed,
                frame=args.frame,
                coverage=args.coverage,
                regions=range(min(args.regions, len(q))),
                block_size=args.block_size,
                executor=executor,
                progress=progress,
                backend=args.backend,
                field_correction=args.field_correction,
            )
    finally:
        elapsed = finish()
    from robocal_uncertainty.app.output_paths import clear_earlier_report

    clear_earlier_report(args.out)
    files = write_map_report(wmap, args.out)
    weak = weakest_region(wmap)
    print(f"{len(wmap)} configurations x {wmap.n_trials} trials in {elapsed:.1f} s; positions in frame {wmap.frame_id}")
    print(
        f"u_pos: median {weak.median_u * 1e6:.1f} um, 95th percentile {weak.p95_u * 1e6:.1f} um, "
        f"max {weak.max_u * 1e6:.1f} um"
    )
    worst = int(wmap.order[0])
    where = ", ".join(f"{v:.3f}" for v in wmap.positions[worst])
    print(f"weakest: configuration {worst + 1} at ({where}) m, reach {wmap.reach[worst]:.3f} m")
    if wmap.field_std_ratio is not None and wmap.field_correction is not None:
        size = np.linalg.norm(wmap.field_correction, axis=1)
        print(
            f"field correction: median {np.median(size) * 1e6:.1f} um, largest {np.max(size) * 1e6:.1f} um; kriging "
            f"std / uncorrected std: median {np.median(wmap.field_std_ratio):.2f}, "
            f"{np.mean(wmap.field_std_ratio >= 0.9):.0%} of the configurations at 0.9 or more (far from the poses)"
        )
    for warning in wmap.warnings:
        print(f"warning: {warning}")
    print(f"map report written to {files.markdown.parent}")
    return 0
