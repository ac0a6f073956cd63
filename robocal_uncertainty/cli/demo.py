"""``robocal-uncertainty demo``: its options (:func:`register`) and its work and printing (:func:`run`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robocal_uncertainty.cli._common import load_robot
from robocal_uncertainty.cli._evaluation import evaluate_and_report
from robocal_uncertainty.cli._options import add_force_arg, add_uncertainty_args
from robocal_uncertainty.report.references import PAPER_TEST_JOINTS_DEG

if TYPE_CHECKING:
    from robocal_uncertainty.uncertainty.sources import SourceRole


DEMO_ROLES: tuple[SourceRole, ...] = ("lambda", "pose_count", "pose_subset")
"""Roles of the paper's selection sources: its regularisation parameter, pose count and pose choice."""


def demo_sources() -> tuple[str, ...]:
    """The paper's five sources, kept: the demo reproduces its Table 2 scenario, a simulated
    campaign with no model error, where the adequacy test finds none and the model-error source
    would add nothing. The validated default's instrument sources, then the sources of
    :data:`DEMO_ROLES`, named by the registry (the demo tests no source name)."""
    from robocal_uncertainty.uncertainty.sources import SOURCE_REGISTRY, default_sources, source_with_role

    instruments = tuple(name for name in default_sources() if SOURCE_REGISTRY[name].role != "model_error")
    return (*instruments, *(source_with_role(role) for role in DEMO_ROLES))


def register(sub: Any) -> None:
    """Add the ``demo`` command and its options to the subparsers `sub`."""
    p = sub.add_parser(
        "demo",
        help="the main job on the embedded default: the arm of Jiang et al. (Table 1), simulated 53-pose campaign, "
        "Table 2 and report",
    )
    p.add_argument("--out", default="robocal_report", help="report directory (default %(default)s)")
    add_force_arg(p, "an earlier report in --out")
    add_uncertainty_args(p, trials_default="20000")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robocal_uncertainty.core import SimulationSettings, simulate_campaign

    sources = demo_sources()
    model = load_robot("paper_arm")
    sim = simulate_campaign(model, SimulationSettings(n_poses=53), seed=args.seed)
    print("Demo: the arm of Jiang et al. (Table 1), a simulated 53-pose campaign with tracker noise +-5 um and")
    print("encoder noise +-0.005 deg (uniform), evaluated at their test joints")
    print(f"({', '.join(f'{v:g}' for v in PAPER_TEST_JOINTS_DEG)}) deg. Sources: {', '.join(sources)}.")
    print()
    test_q = np.radians(np.array(PAPER_TEST_JOINTS_DEG))[None, :]
    result = evaluate_and_report(
        model, sim.campaign, test_q, sources=sources, args=args, out_dir=Path(args.out), label="demo"
    )
    from robocal_uncertainty.core import forward_points

    truth = forward_points(model.layout, sim.true_model.parameter_vector(), test_q)[0]
    inside = [result.poses[0].axes[i].probabilistically_symmetric.contains(float(truth[i])) for i in range(3)]
    print(
        "simulated truth at the test joints: (" + ", ".join(f"{v * 1e3:.4f}" for v in truth) + ") mm; "
        "inside the 95 % intervals: " + ", ".join(f"{a} {'yes' if v else 'no'}" for a, v in zip("xyz", inside))
    )
    from robocal_uncertainty.report.table2 import format_paper_comparison

    print()
    print(format_paper_comparison(result))
    return 0
