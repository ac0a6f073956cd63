"""Held-out accuracy of the model-error field's correction (kriging) and whether its intervals hold.

For random splits of the real UR10 series (B and D), calibrates on the training poses as
``calibrate --json`` does (the session record with its field, written to a calibration file's
dict), and predicts the held-out points as ``fk --field-correction`` does: the calibrated
kinematics plus the field's conditional mean given the training residuals,
``E[delta_c | z] = Cov(delta_c, z) Cov(z)^-1 z`` (``z`` the residuals' contrasts orthogonal to the
fit, ``delta_c`` the calibrated prediction's error; :mod:`robocal_uncertainty.core.field_kriging`).
Prints per row the held-out 3-D RMS without and with the correction, the per-axis fraction of
held-out points inside the 95 % interval of the corrected statement (kriging covariance widened
by the calibration's own folds, plus the held-out point's stated noise; Student-t quantile), the
normalised error RMS, the same coverage with the kriging variance as estimated (no widening) and
of the uncorrected field statement, and the field's hyperparameters.

    python benchmarks/study_field_kriging.py --series D B --train 200 500 1000 --splits 5
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.core import identify
from robocal_uncertainty.core.calibration_file import apply_calibration, calibration_to_dict
from robocal_uncertainty.core.field_kriging import krige, kriging_basis
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty.model_adequacy import pose_noise_covariances
from robocal_uncertainty.uncertainty.sessions.state import session_state

SERIES = {
    "D": ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv",
    "B": ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "series_b" / "measurements_joint_configurations.csv",
}


def one_split(model, campaign, train: np.ndarray, held: np.ndarray) -> dict[str, object]:
    """Calibrate on `train` as ``calibrate --json`` does; correct the held-out points as ``fk --field-correction``."""
    tr, ho = campaign.subset(train), campaign.subset(held)
    cal = identify(model, tr)
    tracker, encoder = TrackerNoise(), EncoderNoise()
    state, _ = session_state(cal, tr, tracker, encoder)
    data = calibration_to_dict(cal, robot="ur10", session=state)
    calibrated = apply_calibration(model, data)
    params, q_c = calibrated.parameter_vector(), ho.joint_positions
    as_estimated = krige(kriging_basis(data, calibrated, cross_validate=False), calibrated.layout, params, q_c)
    basis = kriging_basis(data, calibrated)  # what fk --field-correction uses: widened by the folds
    kriged = krige(basis, calibrated.layout, params, q_c)
    pred = forward_points(calibrated.layout, params, q_c)
    noise_c = pose_noise_covariances(cal, q_c, tracker, encoder, np.linalg.norm(ho.points, axis=1))
    err_plain = ho.points - pred
    err_krig = err_plain - kriged.mean

    def std(cov: np.ndarray) -> np.ndarray:
        return np.sqrt(np.diagonal(cov + noise_c, axis1=1, axis2=2))

    k_t = kriged.coverage_factor()
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e**2, axis=1))))  # noqa: E731
    z = err_krig / std(kriged.covariance)
    return {
        "rms_plain": rms(err_plain),
        "rms_krig": rms(err_krig),
        "inside": np.mean(np.abs(z) <= k_t, axis=0),
        "nrms": np.sqrt(np.mean(z**2, axis=0)),
        "inside_estimated": np.mean(np.abs(err_krig / std(as_estimated.covariance)) <= k_t, axis=0),
        "inside_prior": np.mean(np.abs(err_plain / std(kriged.prior_covariance)) <= k_t, axis=0),
        "factor": float(np.max(basis.factor_axes)) if basis.factor_axes.size else 1.0,
        "c": basis.correlated_fraction,
        "l": basis.length_scale,
        "dof": basis.dof,
        "ratio": float(np.median(kriged.std_ratio)),
    }


def _mean(rows: list[dict[str, object]], key: str) -> np.ndarray:
    return np.mean([r[key] for r in rows], axis=0)


def _pct(values: np.ndarray) -> str:
    return " / ".join(f"{100 * v:.1f}" for v in values)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--series", nargs="+", default=["B", "D"], choices=["B", "D"])
    ap.add_argument("--train", nargs="+", type=int, default=[53, 200, 500, 1000])
    ap.add_argument("--splits", type=int, default=3)
    ap.add_argument("--held-out", type=int, default=300)
    args = ap.parse_args()
    model = load_robot_model(resolve_robot_config("ur10"))
    print(f"kriging study: {args.splits} random splits per row, up to {args.held_out} held-out points per split")
    for name in args.series:
        if not SERIES[name].is_file():
            print(f"series {name}: {SERIES[name]} not found, skipped")
            continue
        campaign = read_tracker_csv(SERIES[name])
        for n_train in args.train:
            if n_train >= campaign.n_poses - 20:
                continue
            rows = []
            for s in range(args.splits):
                perm = np.random.default_rng(np.random.SeedSequence([0, s, 29])).permutation(campaign.n_poses)
                train = np.sort(perm[:n_train])
                held = np.sort(perm[n_train:][: args.held_out])
                rows.append(one_split(model, campaign, train, held))
            mean = functools.partial(_mean, rows)
            each = " ".join(f"{100 * np.min(r['inside']):.1f}" for r in rows)
            plain, krig = mean("rms_plain"), mean("rms_krig")
            print(
                f"series {name} ({campaign.n_poses} poses), {n_train} training, {len(rows)} splits: held-out 3-D RMS "
                f"{plain * 1e3:.3f} mm -> {krig * 1e3:.3f} mm corrected ({(krig / plain - 1) * 100:+.1f} %); "
                f"inside 95 % per axis x / y / z, corrected: {_pct(mean('inside'))} (lowest axis per split {each}), "
                f"normalised RMS {' / '.join(f'{v:.2f}' for v in mean('nrms'))}; without the folds' widening "
                f"{_pct(mean('inside_estimated'))} (largest factor {mean('factor'):.2f}); uncorrected, the field's "
                f"statement {_pct(mean('inside_prior'))}; c {mean('c'):.2f}, l {mean('l'):.2f} rad, "
                f"dof {mean('dof'):.0f}, median std ratio {mean('ratio'):.2f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
