"""``robocal-uncertainty import-csv``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

from robocal_uncertainty.cli._common import count
from robocal_uncertainty.cli._options import add_force_arg
from robocal_uncertainty.errors import ConfigError


def register(sub: Any) -> None:
    """Add the ``import-csv`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("import-csv", help="convert a tracker CSV export into a campaign MCAP")
    p.add_argument("csv", help="tracker CSV (comma-, semicolon- or tab-separated, units in the header)")
    p.add_argument("--out", required=True, help="campaign .mcap to write")
    p.add_argument(
        "--length-unit", help="unit of length columns whose header states none: m, mm, um (default: none assumed)"
    )
    p.add_argument(
        "--angle-unit", help="unit of joint columns whose header states none: rad, deg (default: none assumed)"
    )
    p.add_argument(
        "--joint-columns",
        help="comma list of the joint column names, in joint order (default: columns named *joint* or q1, q2, ...)",
    )
    p.add_argument("--skip-invalid", action="store_true", help="drop invalid rows instead of failing (default: fail)")
    p.add_argument(
        "--orientation-columns",
        help="comma list of the three Euler-angle columns of a 6-DOF probe, in the convention's order "
        "(ipa profile: measurement_rx,measurement_ry,measurement_rz; default: points only)",
    )
    p.add_argument("--orientation-unit", help="unit of orientation columns whose header states none: rad, deg")
    p.add_argument(
        "--orientation-convention",
        help="Euler convention of the orientation columns: intrinsic_xyz, extrinsic_xyz, intrinsic_zyx, "
        "intrinsic_zyz (ipa: intrinsic_xyz; giving it alone reads the ipa orientations)",
    )
    add_force_arg(p, "the campaign file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.bagio import write_campaign
    from robocal_uncertainty.importers import read_tracker_csv

    joint_columns = None
    if args.joint_columns is not None:
        joint_columns = [name.strip() for name in args.joint_columns.split(",") if name.strip()]
        if not joint_columns:
            raise ConfigError("--joint-columns needs a comma list of column names")
    orientation_columns = None
    if args.orientation_columns is not None:
        orientation_columns = [name.strip() for name in args.orientation_columns.split(",") if name.strip()]
    campaign = read_tracker_csv(
        args.csv,
        length_unit=args.length_unit,
        angle_unit=args.angle_unit,
        skip_invalid=args.skip_invalid,
        joint_columns=joint_columns,
        orientation_columns=orientation_columns,
        orientation_unit=args.orientation_unit,
        orientation_convention=args.orientation_convention,
    )
    write_campaign(args.out, campaign, overwrite=args.force)
    skipped: Any = campaign.metadata.get("skipped_rows") or []  # row numbers in the metadata
    print(
        f"wrote {args.out}: {count(campaign.n_poses, 'pose')}, joints {', '.join(campaign.joint_names)}, "
        f"points in the {campaign.frame} frame ({campaign.frame_id})"
        + (f", {count(len(skipped), 'invalid row')} skipped" if skipped else "")
    )
    return 0
