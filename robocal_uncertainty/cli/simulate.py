"""``robocal-uncertainty simulate``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from robocal_uncertainty.cli._common import count, load_robot
from robocal_uncertainty.cli._options import add_force_arg, add_noise_args


def register(sub: Any) -> None:
    """Add the ``simulate`` command and its options to the subparsers `sub`."""
    p = sub.add_parser("simulate", help="write a simulated campaign MCAP (truth in a sidecar .truth.json)")
    p.add_argument("--robot", default="paper_arm", help="robot YAML file or shipped model name (default %(default)s)")
    p.add_argument("--out", required=True, help="campaign .mcap to write; the truth goes to the same name .truth.json")
    p.add_argument("--poses", type=int, default=53, help="number of measured poses (default %(default)s)")
    p.add_argument(
        "--frame",
        choices=("base", "tracker"),
        default="base",
        help="points in the robot base frame or in a tracker frame with an unknown base (default %(default)s)",
    )
    add_noise_args(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated robot, poses and noise (default 0)")
    add_force_arg(p, "the campaign and truth files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.app import simulate
    from robocal_uncertainty.core import EncoderNoise, SimulationSettings, TrackerNoise

    model = load_robot(args.robot)
    settings = SimulationSettings(
        n_poses=args.poses,
        frame=args.frame,
        tracker_noise=TrackerNoise(a=args.tracker_noise_um * 1e-6, b=args.tracker_noise_um_per_m * 1e-6),
        encoder_noise=EncoderNoise(half_width=float(np.radians(args.encoder_noise_deg))),
    )
    files = simulate(model, settings, args.out, seed=args.seed, overwrite=args.force)
    print(
        f"wrote {files.campaign_path} ({count(files.simulation.campaign.n_poses, 'pose')}, "
        f"points in the {args.frame} frame) "
        f"and truth {files.truth_path}"
    )
    return 0
