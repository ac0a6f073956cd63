"""Per-split diagnosis of the model-error field's held-out statement (series B or D, points).

For each of `splits` random training sets of the study's scheme
(``benchmarks/study_model_error_field.py``), prints the field's estimate (``c``, ``l``, ``u``, the
scale's degrees of freedom, the shape's mean Wishart degrees of freedom) and the held-out
coverage per axis and in the 3-D region. Pooled: the held-out errors' squared Mahalanobis
distance (in the Monte Carlo's covariance) against the draws' (its 95 % quantile over its mean),
and the region's coverage if each split's scale were set to what its own held-out errors show
(is the miss the scale, or the shape?). Records the estimates by wrapping ``estimate_field`` and
the region test of ``validate_holdout``; changes nothing.

    python benchmarks/diagnose_model_error_field.py D 53 30
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import study_model_error_field as study

from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty import (
    UncertaintySettings,
    default_sources,
    holdout,
)
from robocal_uncertainty.uncertainty.calibration import preparation


def main() -> int:
    series, n_train, n_splits = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    estimates, regions = [], []
    estimate_field, inside_regions = preparation.estimate_field, holdout._inside_regions

    def recorded_estimate(*args, **kwargs):  # type: ignore[no-untyped-def]
        estimates.append(estimate_field(*args, **kwargs))
        return estimates[-1]

    def recorded_regions(pred, points, levels):  # type: ignore[no-untyped-def]
        centred = pred - pred.mean(axis=0)
        chol = np.linalg.cholesky(np.einsum("mpi,mpj->pij", centred, centred) / (pred.shape[0] - 1))
        d2 = np.sum(np.linalg.solve(chol[None], centred[..., None])[..., 0] ** 2, axis=-1)
        dp2 = np.sum(np.linalg.solve(chol, (points - pred.mean(axis=0))[..., None])[..., 0] ** 2, axis=-1)
        regions.append((dp2, np.quantile(d2, 0.95, axis=0), d2.mean(axis=0)))
        return inside_regions(pred, points, levels)

    preparation.estimate_field = recorded_estimate  # type: ignore[assignment]
    holdout._inside_regions = recorded_regions  # type: ignore[assignment]
    model = load_robot_model(resolve_robot_config("ur10"))
    campaign = read_tracker_csv(study.SERIES_D if series == "D" else study.SERIES_B)
    n_held = min(200, campaign.n_poses - n_train)
    splits = study._splits(campaign.n_poses, n_train, n_held, n_splits, 0)
    settings = UncertaintySettings(sources=default_sources(False), model_error="field")
    v = holdout.validate_holdout(model, campaign, splits=splits, settings=settings, trials=1000, seed=0)
    axes = " ".join(f"{a.inside_fraction * 100:.1f}" for a in v.axes)
    print(
        f"series {series}, {n_train} training poses, {n_splits} splits: per axis {axes} %, region "
        f"{v.region_inside_fraction * 100:.1f} %"
    )
    z = (v.errors / v.standard_uncertainties).reshape(n_splits, n_held, 3)
    for i, (e, (dp2, q95, _)) in enumerate(zip(estimates, regions)):
        u = ", ".join(f"{x * 1e6:.0f}" for x in e.standard_uncertainty)
        k = "none" if e.shape_dof is None else f"{e.shape_dof:.1f}"
        print(
            f"  split {i}: c {e.correlated_fraction:.2f}, l {e.length_scale:.2f} rad, u ({u}) um, scale dof "
            f"({', '.join(f'{x:.0f}' for x in e.scale_dof)}), shape dof {k}: region "
            f"{np.mean(dp2 <= q95) * 100:.1f} %, axes {np.round(np.mean(np.abs(z[i]) < 1.96, axis=0) * 100, 1)}"
        )
    dp2, q95, md2 = (np.concatenate(x) for x in zip(*regions))
    ratio = (dp2 / md2).reshape(n_splits, n_held)
    own = ratio / ratio.mean(axis=1, keepdims=True)
    own_inside = np.mean(own * md2.reshape(own.shape) <= q95.reshape(own.shape)) * 100
    print(
        f"held-out 95 % quantile / mean of the squared distance {np.quantile(ratio, 0.95) / ratio.mean():.2f}, "
        f"drawn {np.mean(q95 / md2):.2f}; region with each split's own scale {own_inside:.1f} %"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
