"""``robocal-uncertainty suggest``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.cli._common import (
    SOURCES_DEFAULT_HELP,
    campaign_and_robot,
    count,
    default_sources,
    joint_configurations,
    parse_lambda,
    read_test_joints,
)
from robocal_uncertainty.cli._evaluation import uncertainty_settings
from robocal_uncertainty.cli._options import (
    add_backend_arg,
    add_campaign_args,
    add_force_arg,
    add_frame_and_convergence_args,
    add_model_error_arg,
    add_noise_args,
)
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sources import sources_help


def _suggestion_joints(q: NDArray[np.float64], unit: str) -> list[float]:
    """Joint positions [rad] in `unit` ("rad" or "deg")."""
    return [float(v) for v in (np.degrees(q) if unit == "deg" else q)]


def _format_suggestions(result: Any, unit: str) -> str:
    """The suggestion table: rank, joints in `unit`, predicted and Monte Carlo RMS u_pos in µm."""
    digits = 4 if unit == "deg" else 6
    header = [
        "rank",
        *(f"{name} / {unit}" for name in result.joint_names),
        "predicted RMS u_pos / µm",
        "Monte Carlo RMS u_pos / µm",
    ]

    def um(value: float | None) -> str:
        return "-" if value is None else f"{value * 1e6:.3f}"

    rows = [["now", *([""] * len(result.joint_names)), um(result.current_u_m), um(result.monte_carlo_current_u_m)]]
    for rank, s in enumerate(result.suggestions, start=1):
        joints = (f"{v:.{digits}f}" for v in _suggestion_joints(s.joint_positions, unit))
        rows.append([str(rank), *joints, um(s.predicted_u_m), um(s.monte_carlo_u_m)])
    widths = [max(len(row[c]) for row in [header, *rows]) for c in range(len(header))]
    lines = ["  ".join(cell.rjust(w) for cell, w in zip(row, widths)) for row in [header, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _suggestions_dict(
    result: Any, model: Any, args: argparse.Namespace, test_q: NDArray[np.float64], settings: Any
) -> dict[str, Any]:
    """The suggestions as a robot program reads them: SI units, named in every key."""
    s = result.suggestions
    return {
        "command": "robocal-uncertainty suggest",
        "robot": model.name,
        "campaign": str(args.campaign),
        "units": {
            "_rad": "radian",
            "_deg": "degree",
            "_m": "metre (u_pos = sqrt(trace of the tool-position covariance), RMS over the test configurations)",
            "_m2": "square metre",
        },
        "joint_names": list(result.joint_names),
        "frame_id": result.frame_id,
        "frame": args.frame,
        "sources": list(settings.sources),
        "tracker_noise": {"a_m": settings.tracker_noise.a, "b_m_per_m": settings.tracker_noise.b},
        "encoder_noise_half_width_rad": settings.encoder_noise.half_width,
        "test_joint_positions_rad": test_q.tolist(),
        "candidates": {
            "file": args.candidates_file,
            "count": len(result.candidates),
            "seed": None if args.candidates_file else result.seed,
        },
        "seed": result.seed,
        "monte_carlo_trials": result.trials,
        **({"monte_carlo_backend": _backend_dict(result.backend)} if result.backend is not None else {}),
        "current_rms_u_pos_m": result.current_u_m,
        "monte_carlo_current_rms_u_pos_m": result.monte_carlo_current_u_m,
        "suggestions": [
            {
                "rank": rank,
                "joint_positions_rad": _suggestion_joints(p.joint_positions, "rad"),
                "joint_positions_deg": _suggestion_joints(p.joint_positions, "deg"),
                "reduction_m2": p.reduction_m2,
                "predicted_rms_u_pos_m": p.predicted_u_m,
                "monte_carlo_rms_u_pos_m": p.monte_carlo_u_m,
            }
            for rank, p in enumerate(s, start=1)
        ],
    }


def _backend_dict(backend: Any) -> dict[str, str]:
    return {"name": backend.name, "version": backend.version, "requested": backend.requested}


def _suggestions_csv(result: Any, unit: str) -> str:
    """One row of joint positions per suggestion, best first, in `unit` (readable back as a
    ``--joints-file``, ``--test-joints-file`` or ``--candidates-file``)."""
    lines = [
        f"# robocal-uncertainty suggest: next-best poses, best first; joint positions in {unit}",
        ",".join(f"{name}_{unit}" for name in result.joint_names),
    ]
    lines += [",".join(repr(v) for v in _suggestion_joints(s.joint_positions, unit)) for s in result.suggestions]
    return "\n".join(lines) + "\n"


def register(sub: Any) -> None:
    """Add the ``suggest`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "suggest",
        help="next-best poses: the configurations whose measurement lowers the uncertainty at the test "
        "configurations most (first-order ranking, optional Monte Carlo check)",
    )
    add_campaign_args(p)
    p.add_argument("--test-joints", nargs="+", help="joint values of the test configurations, n_joints each")
    p.add_argument("--test-joints-file", help="CSV/whitespace file of test configurations, one per row")
    p.add_argument(
        "--degrees",
        action="store_true",
        help="joint values (--test-joints, --candidates-file, the printed table and --csv) are in degrees "
        "(default radians)",
    )
    p.add_argument("--count", type=int, default=5, help="number of poses suggested, best first (default %(default)s)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--candidates",
        type=int,
        default=500,
        help="rank this many configurations drawn uniformly inside the joint limits less 0.05 rad, with --seed "
        "(default %(default)s)",
    )
    where.add_argument("--candidates-file", help="rank these configurations instead: CSV/whitespace file, one per row")
    p.add_argument(
        "--check",
        type=int,
        default=0,
        help="Monte Carlo check of the first K suggestions: the campaign with suggestions 1..k added as simulated "
        "measurements is evaluated (default %(default)s: none)",
    )
    p.add_argument("--trials", type=int, default=2000, help="Monte Carlo trials per check (default %(default)s)")
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the candidate draw and of every check (default %(default)s)"
    )
    p.add_argument(
        "--sources",
        default=None,
        help="the ranking weighs the poses with the tracker and encoder noise (each only if listed); the checks use "
        f"every listed source: {sources_help()} ({SOURCES_DEFAULT_HELP})",
    )
    p.add_argument("--lambda", dest="lambda_", default="auto", help="auto (L-curve corner), gcv, or a fixed value")
    add_noise_args(p)
    p.add_argument("--json", help="write the suggestions to this JSON file (SI units, also degrees)")
    p.add_argument(
        "--csv",
        dest="csv_out",
        help="write the suggested joint positions to this CSV file, best first, in rad (deg with --degrees)",
    )
    add_force_arg(p, "the --json and --csv files")
    add_model_error_arg(p)
    add_frame_and_convergence_args(p)
    add_backend_arg(p)
    p.set_defaults(func=run, lambda_range=None, min_poses=None, subset_size=None)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import suggest_poses
    from robocal_uncertainty.core import identify
    from robocal_uncertainty.kernels import get_backend
    from robocal_uncertainty.uncertainty import parse_sources

    get_backend(args.backend)  # an unknown or missing backend stops here, before any work
    campaign, model = campaign_and_robot(args)
    campaign = campaign.reorder_joints(model.joint_names)
    test_q = read_test_joints(args, model)
    candidates = None
    if args.candidates_file:
        candidates = joint_configurations(
            model, args.candidates_file, None, degrees=args.degrees, flag="--candidates-file", noun="candidate"
        )
        if args.count > len(candidates):
            msg = (
                f"--count {args.count} is more than the {count(len(candidates), 'configuration')} "
                f"in --candidates-file {args.candidates_file}"
            )
            raise ConfigError(msg)
    settings = uncertainty_settings(args, None, parse_sources(default_sources(args.sources, campaign)))
    lambda_ = parse_lambda(args.lambda_)
    calibration = identify(model, campaign, lambda_=lambda_, accept_unconverged=args.accept_unconverged)
    result = suggest_poses(
        model,
        campaign,
        test_q,
        settings=settings,
        calibration=calibration,
        lambda_=lambda_,
        candidates=candidates,
        n_candidates=args.candidates,
        count=args.count,
        monte_carlo_check=args.check,
        trials=args.trials,
        seed=args.seed,
        frame=args.frame,
        backend=args.backend,
    )
    unit = "deg" if args.degrees else "rad"
    source = (
        f"the {count(len(result.candidates), 'configuration')} of {args.candidates_file}"
        if args.candidates_file
        else f"{len(result.candidates)} candidates drawn inside the joint limits (random seed {args.seed})"
    )
    print(f"Next-best poses for {model.name} ({campaign.n_poses} poses measured), ranked among {source}")
    print(
        f"u_pos = sqrt(trace of the tool-position covariance), RMS over the "
        f"{count(len(test_q), 'test configuration')}, frame {result.frame_id}; sources {', '.join(settings.sources)}"
    )
    print(_format_suggestions(result, unit))
    if result.trials:
        backend = f"; backend {result.backend.describe()}" if result.backend is not None else ""
        print(
            f"Monte Carlo: {result.trials} trials, random seed {result.seed}, with suggestions 1..rank added as "
            f"simulated measurements at the calibrated model's points{backend}"
        )
    if args.json:
        text = json.dumps(_suggestions_dict(result, model, args, test_q, settings), indent=2, allow_nan=False)
        Path(args.json).write_text(text + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    if args.csv_out:
        Path(args.csv_out).write_text(_suggestions_csv(result, unit), encoding="utf-8")
        print(f"wrote {args.csv_out}")
    return 0
