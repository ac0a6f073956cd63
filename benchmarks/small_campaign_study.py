"""Small campaigns: does the default statement hold when calibrated on few poses?

For each campaign size n (10, 15, 20, 30, 53 poses) draw ``--draws`` random training sets
from a long series, calibrate and evaluate on them with the default sources (tracker,
encoder, residual), predict every other pose of the series and count how many of them fall
inside the 95 % JCGM 102 region of their prediction; print the fraction inside, the RMS of
the normalised error over the three axes, and whether the statement flags itself as not
trustworthy (``ModelAdequacy.trustworthy``). The rule the flag follows is stated in
:mod:`robocal_uncertainty.uncertainty.model_adequacy`; it is not tuned to any series.

Series: the shipped UR10 laser-tracker campaign (632 poses, real model error), and
simulated UR10 campaigns of 632 poses in a tracker frame with unmodelled joint errors
(gear transmission error and gravity sag, ``UnmodelledErrors``) of a few sizes.

    python benchmarks/small_campaign_study.py                 # UR10 series and simulations
    python benchmarks/small_campaign_study.py --series ur10   # the shipped series only
    # the slow check's two 53-pose draws of the shipped series, each printed:
    python benchmarks/small_campaign_study.py --series ur10 --sizes 53 --draws 2 --trials 1000 --per-draw

Run time: about 2 minutes on two cores with the defaults.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.simulation import SimulationSettings, UnmodelledErrors, simulate_campaign
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty.holdout import split_campaign, validate_holdout
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy
from robocal_uncertainty.uncertainty.sources import UncertaintySettings

UR10_CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
SIZES = (10, 15, 20, 30, 53)
SIMULATED_ERRORS = ((2e-4, 4e-4), (5e-5, 1e-4))
"""(gear transmission amplitude, gravity sag) [rad] of the simulated series."""


def study(
    model: RobotModel,
    campaign: Campaign,
    sizes: tuple[int, ...],
    draws: int,
    trials: int,
    seed: int,
    model_error: str | None = None,
    *,
    per_draw: bool = False,
    first_draw: int = 0,
) -> list[dict[str, float]]:
    """One row per size: pooled inside fraction, normalised RMS, flagged draws (`model_error`:
    ``field`` or ``independent``, None the default statement's; `per_draw`: print each draw's;
    `first_draw`: the first draw's index, so that a run can extend another's)."""
    settings = UncertaintySettings() if model_error is None else UncertaintySettings(model_error=model_error)  # type: ignore[arg-type]
    rows = []
    for n in sizes:
        inside, norm_sq, count, flagged = 0.0, 0.0, 0, 0
        for d in range(first_draw, first_draw + draws):
            split = split_campaign(campaign.n_poses, n_train=n, seed=seed + 1000 * n + d)
            start = time.perf_counter()
            val = validate_holdout(
                model, campaign, splits=split, settings=settings, trials=trials, seed=seed + d, workers=1
            )
            k = val.n_held_out
            if per_draw:
                z = val.errors / val.standard_uncertainties
                axes = ", ".join(f"{a.inside_fraction * 100:.1f}" for a in val.axes)
                print(
                    f"  {n} poses, draw {d}: region {val.region_inside_fraction * 100:.1f} %, per axis {axes} %, "
                    f"normalised RMS {', '.join(f'{v:.3f}' for v in np.sqrt(np.mean(z**2, axis=0)))}, "
                    f"{time.perf_counter() - start:.1f} s",
                    flush=True,
                )
            inside += val.region_inside_fraction * k
            norm_sq += float(np.sum((val.errors / val.standard_uncertainties) ** 2))
            count += k
            flagged += int(not val.folds[0].trustworthy)
        rows.append(
            {
                "n": n,
                "inside": inside / count,
                "normalised_rms": float(np.sqrt(norm_sq / (3 * count))),
                "flagged": flagged,
                "draws": draws,
            }
        )
    return rows


def simulated_series(model: RobotModel, gear: float, sag: float, seed: int) -> tuple[Campaign, np.ndarray]:
    """A simulated 632-pose UR10 series in a tracker frame with unmodelled joint errors, and the
    model error u (m, per axis) the adequacy assessment finds over all its poses."""
    sim = simulate_campaign(
        model,
        SimulationSettings(
            n_poses=632, frame="tracker", unmodelled=UnmodelledErrors(gear_amplitude=gear, compliance=sag)
        ),
        seed=seed,
    )
    full = identify(model, sim.campaign)
    s = UncertaintySettings()
    q = sim.campaign.reorder_joints(model.joint_names).joint_positions
    ad = assess_model_adequacy(full, q, s.tracker_noise, s.encoder_noise, np.linalg.norm(sim.campaign.points, axis=1))
    return sim.campaign, ad.standard_uncertainty


def _print(title: str, rows: list[dict[str, float]]) -> None:
    print(f"\n{title}")
    print("| poses | inside the 95 % region | normalised error RMS | flagged not trustworthy |")
    print("| --- | --- | --- | --- |")
    for r in rows:
        print(
            f"| {r['n']} | {100 * r['inside']:.1f} % | {r['normalised_rms']:.2f} | "
            f"{r['flagged']} of {r['draws']} draws |"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--series", choices=("ur10", "simulated", "both"), default="both")
    parser.add_argument("--draws", type=int, default=4, help="training sets per size (default %(default)s)")
    parser.add_argument("--trials", type=int, default=2000, help="Monte Carlo trials per draw (default %(default)s)")
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--model-error",
        choices=("field", "independent"),
        default=None,
        help="model error drawn (default: the default's)",
    )
    parser.add_argument("--per-draw", action="store_true", help="print every draw's coverage too")
    parser.add_argument(
        "--first-draw", type=int, default=0, help="index of the first draw (extends a run of that many draws)"
    )
    args = parser.parse_args(argv)
    model = load_robot_model(resolve_robot_config("ur10"))
    sizes = tuple(args.sizes)

    def study_of(campaign: Campaign) -> list[dict[str, float]]:
        """The study of one series with the command line's settings."""
        return study(
            model,
            campaign,
            sizes,
            args.draws,
            args.trials,
            args.seed,
            args.model_error,
            per_draw=args.per_draw,
            first_draw=args.first_draw,
        )

    if args.series in ("ur10", "both"):
        campaign = read_tracker_csv(UR10_CSV)
        _print(f"UR10 series ({campaign.n_poses} poses), {args.draws} draws per size", study_of(campaign))
    if args.series in ("simulated", "both"):
        for gear, sag in SIMULATED_ERRORS:
            campaign, u = simulated_series(model, gear, sag, args.seed + 7)
            _print(
                f"simulated UR10, 632 poses, gear error {gear * 1e6:.0f} urad, sag {sag * 1e6:.0f} urad "
                f"(model error u = {', '.join(f'{v * 1e6:.0f}' for v in u)} um over all poses), "
                f"{args.draws} draws per size",
                study_of(campaign),
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
