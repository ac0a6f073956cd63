"""``robocal-uncertainty fk``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from robocal_uncertainty.cli._common import joint_configurations, load_robot
from robocal_uncertainty.cli._options import add_force_arg, add_urdf_chain_args

FACTORS_COMPUTED_NOTE = (
    "the calibration file stores no cross-validated kriging factors (written before they were stored): computed "
    "now from its poses (5 refits; recalibrate with 'calibrate --json' to store them and skip this)"
)
"""What a correction of an older calibration file says (the commands with --field-correction)."""


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
    p.add_argument(
        "--field-correction",
        action="store_true",
        help="add the calibration's model-error field at these configurations (its conditional mean given the "
        "calibration residuals, kriging) and print its standard uncertainty; needs a --calibration that carries "
        "model_error.field (a URDF cannot carry it). Helps near the calibration poses of a dense campaign, fades "
        "to nothing far from them",
    )
    p.add_argument("--json", help="also write both frames' points to this JSON file (SI units)")
    add_force_arg(p, "the --json file")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from robocal_uncertainty.app import tool_points
    from robocal_uncertainty.core.calibration_file import apply_calibration, read_calibration
    from robocal_uncertainty.core.field_kriging import kriging_basis
    from robocal_uncertainty.errors import ConfigError

    model = load_robot(args.robot, base_link=args.base_link, tip_link=args.tip_link, tool_point=args.tool_point)
    basis = None
    if args.calibration:
        where = f"calibration {args.calibration}"
        data = read_calibration(args.calibration)
        model = apply_calibration(model, data, where=where)
        if args.field_correction:
            basis = kriging_basis(data, model, where=where)
    elif args.field_correction:
        msg = "--field-correction needs a --calibration (the field and its residuals are in the calibration file)"
        raise ConfigError(msg)
    q = joint_configurations(
        model, args.joints_file, args.joints, degrees=args.degrees, flag="--joints", noun="configuration"
    )
    points = tool_points(model, q, calibrated=bool(args.calibration), frame=args.frame, field_correction=basis)
    print(
        f"# tool point of the {points.model} {model.name} model in frame {points.frame_id} ({points.frame} frame), mm"
    )
    axes = ("x", "y", "z")
    if points.correction is None or points.correction_covariance is None:
        print(f"# x_{points.frame_id} y_{points.frame_id} z_{points.frame_id}")
        for row in points.points:
            print(" ".join(f"{v * 1e3:.6f}" for v in row))
    else:
        print(
            f"# with the model-error field's correction (kriging; k = {points.coverage_factor:.3f} for 95 % per axis): "
            "point, correction d, standard uncertainty u of the corrected point (field and parameters, not a new "
            "measurement's noise), ratio = kriging std / uncorrected std (1: far from every calibration pose)"
        )
        print(
            "# "
            + " ".join(f"{a}_{points.frame_id}" for a in axes)
            + " "
            + " ".join(f"d{a}" for a in axes)
            + " "
            + " ".join(f"u_{a}" for a in axes)
            + " ratio"
        )
        if basis is not None and basis.factors_source == "computed":
            print(f"# note: {FACTORS_COMPUTED_NOTE}")
        if basis is not None and basis.dof < 20:
            # Measured on held-out real poses: with 53 calibration poses (6 degrees of freedom) the
            # intervals held 98-99 % for a 5-7 % gain (benchmarks/study_field_kriging.py).
            print(
                f"# warning: the field's scale has {basis.dof:.0f} degrees of freedom ({len(basis.residuals)} "
                "calibration poses): the field is barely identified, its intervals are wider than the evidence"
            )
        std = np.sqrt(np.clip(np.diagonal(points.correction_covariance, axis1=1, axis2=2), 0.0, None))
        ratio = points.std_ratio if points.std_ratio is not None else np.ones(len(std))
        for row, d, u, r in zip(points.points, points.correction, std, ratio):
            print(" ".join(f"{v * 1e3:.6f}" for v in (*row, *d, *u)) + f" {r:.3f}")
    if args.json:
        Path(args.json).write_text(json.dumps(points.to_dict(), indent=2) + "\n", encoding="utf-8")
    return 0
