"""Does the model error's covariance vary over the workspace? Evidence on the UR10 series B and D.

Calibrates on every pose of a series and whitens each residual three ways: by the covariance of
all residuals (one shape for the whole workspace), by that covariance scaled to the residuals of
its `--neighbours` nearest configurations (chordal joint distance; the scale varies, the shape
does not), and by the covariance of those neighbours (scale and shape vary). Prints the
multivariate kurtosis of each, as a ratio to a normal's (1: normal; a variance mixture is
heavier), and the spread of the neighbourhoods' per-axis standard deviations and correlations.
The residual source's field draws a Wishart local covariance because of what this shows
(:mod:`robocal_uncertainty.uncertainty.model_error_draws`).

    python benchmarks/study_model_error_shape.py            # both series, 60 neighbours
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.model_error_field import chordal_distance
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

SERIES = {
    "D": ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv",
    "B": ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "series_b" / "measurements_joint_configurations.csv",
}


def _kurtosis_ratio(quad: np.ndarray, d: int) -> float:
    """Mardia's kurtosis of squared Mahalanobis distances over a normal's ``d (d + 2)``, scale-free."""
    return float(np.mean(quad**2) / np.mean(quad) ** 2 * d / (d + 2))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--series", nargs="+", default=["D", "B"], choices=sorted(SERIES))
    ap.add_argument("--neighbours", type=int, default=60)
    args = ap.parse_args()
    model = load_robot_model(resolve_robot_config("ur10"))
    k = args.neighbours
    for name in args.series:
        if not SERIES[name].is_file():
            print(f"series {name}: {SERIES[name]} not found, skipped")
            continue
        campaign = read_tracker_csv(SERIES[name]).reorder_joints(model.joint_names)
        r = np.asarray(identify(model, campaign).residuals)
        n, d = r.shape
        cov = r.T @ r / n
        near = np.argsort(chordal_distance(campaign.joint_positions, campaign.joint_positions), axis=1)[:, 1 : k + 1]
        local = np.einsum("nki,nkj->nij", r[near], r[near]) / k  # neighbours only, the pose itself left out
        scale = np.trace(np.linalg.solve(cov[None], local), axis1=1, axis2=2) / d
        one = np.einsum("ni,ni->n", r, np.linalg.solve(cov[None], r[..., None])[..., 0])
        scaled = one / scale
        shaped = np.einsum("ni,ni->n", r, np.linalg.solve(local, r[..., None])[..., 0])
        sd = np.sqrt(np.diagonal(local, axis1=1, axis2=2))
        corr = local / (sd[:, :, None] * sd[:, None, :])
        pairs = [(0, 1), (0, 2), (1, 2)]
        print(
            f"series {name} ({n} poses), residual u = "
            f"({', '.join(f'{v * 1e6:.0f}' for v in np.sqrt(np.diag(cov)))}) um:"
        )
        print(
            f"  kurtosis / normal's: one covariance {_kurtosis_ratio(one, d):.2f}, scaled to {k} neighbours "
            f"{_kurtosis_ratio(scaled, d):.2f}, the {k} neighbours' covariance {_kurtosis_ratio(shaped, d):.2f}"
        )
        lo, hi = np.percentile(sd, [10, 90], axis=0) * 1e6
        print("  neighbourhood u, 10-90 %: " + ", ".join(f"{a:.0f}-{b:.0f}" for a, b in zip(lo, hi)) + " um (x, y, z)")
        c10, c90 = (np.percentile([corr[:, i, j] for i, j in pairs], q, axis=1) for q in (10, 90))
        print(
            "  neighbourhood correlation, 10-90 %: "
            + ", ".join(f"{a:+.2f} to {b:+.2f}" for a, b in zip(c10, c90))
            + " (xy, xz, yz)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
