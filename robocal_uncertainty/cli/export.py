"""``robocal-uncertainty export``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from robocal_uncertainty.cli._options import add_force_arg, add_urdf_chain_args
from robocal_uncertainty.core.robot_formats.registry import EXPORT_FORMATS


def sidecar_path(out: str | Path) -> Path:
    """Default file of the uncertainty sidecar: ``OUT.uncertainty.json``."""
    return Path(f"{out}.uncertainty.json")


def register(sub: Any) -> None:
    """Add the ``export`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "export",
        help="write a calibration as a corrected URDF, UR kinematics YAML or robot YAML (uncertainty beside it)",
    )
    p.add_argument("calibration", help="calibration JSON from 'calibrate --json'")
    p.add_argument(
        "--format",
        required=True,
        choices=EXPORT_FORMATS,
        dest="export_format",
        help="urdf: the robot's URDF with corrected joint origins; ur-kinematics: ur_description's "
        "kinematics_params_file; yaml: the package's robot YAML",
    )
    p.add_argument("--out", required=True, help="file to write")
    p.add_argument(
        "--robot",
        help="the robot the calibration was identified on: robot YAML, shipped model name or URDF "
        "(default: the calibration's own 'robot')",
    )
    add_urdf_chain_args(p)
    p.add_argument(
        "--urdf",
        help="for a robot YAML model: the URDF whose joint origins to correct (e.g. the expanded ur_description "
        "URDF); the shipped ur10 has one",
    )
    p.add_argument("--uncertainty-out", help="the parameters' uncertainty sidecar JSON (default: OUT.uncertainty.json)")
    add_force_arg(p, "the --out and sidecar files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app.export import export_calibration
    from robocal_uncertainty.app.output_paths import check_output_file
    from robocal_uncertainty.core.calibration_file import read_calibration
    from robocal_uncertainty.core.robot_formats import load_robot_source
    from robocal_uncertainty.errors import ConfigError

    data = read_calibration(args.calibration)
    robot = args.robot or data.get("robot")
    if not isinstance(robot, str) or not robot:
        msg = f"calibration {args.calibration} names no robot: give --robot"
        raise ConfigError(msg)
    sidecar = Path(args.uncertainty_out) if args.uncertainty_out else sidecar_path(args.out)
    for path, option in ((Path(args.out), "--out"), (sidecar, "--uncertainty-out")):
        check_output_file(path, force=bool(args.force), option=option)
        if path.resolve() == Path(args.calibration).resolve():
            msg = f"{option} {path} is the calibration being exported"
            raise ConfigError(msg)
    source = load_robot_source(robot, base_link=args.base_link, tip_link=args.tip_link, urdf=args.urdf)
    export = export_calibration(data, source, args.export_format, where=f"calibration {args.calibration}")
    Path(args.out).write_text(export.text, encoding="utf-8")
    sidecar.write_text(json.dumps(export.sidecar, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out} ({args.export_format}, robot {source.model.name!r})")
    if isinstance(data.get("model_error"), dict) and data["model_error"].get("field") is not None:
        print(
            f"note: {args.out} cannot carry the model-error field's correction (a kriged offset, not a kinematic "
            f"parameter): fk --field-correction --calibration {args.calibration} applies it"
        )
    if export.tip_link:
        x, y, z = (1e3 * v for v in export.point_in_tip)
        print(f"measured point in {export.tip_link}: ({x:.4f}, {y:.4f}, {z:.4f}) mm (calibrated; not part of the URDF)")
    determined = sum(1 for p in export.sidecar["parameters"] if p["determined_by_data"])
    print(
        f"wrote {sidecar}: {len(export.sidecar['parameters'])} parameters, {determined} determined by the data; "
        + ("covariance included" if export.sidecar["covariance"] is not None else "standard uncertainties only")
    )
    return 0
