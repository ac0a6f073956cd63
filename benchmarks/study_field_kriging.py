"""How much the model-error field's conditional mean (kriging) improves held-out predictions.

For random splits of the real UR10 series (B and D), calibrates on the training poses, estimates
the field from the training residuals alone (as the residual source does), and predicts the
held-out points twice: with the calibrated kinematics, and with the kinematics plus the best
linear predictor of their error given the training residuals,

``E[delta_c | z] = Cov(delta_c, z) Cov(z)^-1 z``, ``z = Q^T r_t = Q^T (e_t + eps_t)``,
``delta_c = e_c - J_c G (e_t + eps_t)`` (``Q`` orthonormal, orthogonal to the fit's Jacobian ``A``)

(``G`` the fit's gain, ``A`` its Jacobian, ``e`` the field, ``eps`` the stated noise). Prints the
held-out 3-D RMS error with and without the correction, and the fraction of held-out points
inside 95 % per-axis intervals from the kriging variance (``Cov(delta_c) - Cov(delta_c, z)
Cov(z)^-1 Cov(z, delta_c)`` plus the held-out point's tracker noise).

    python benchmarks/study_field_kriging.py --series B --train 200 500 1000 --splits 3

This measures; no command applies the correction yet (a calibrated URDF cannot carry it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import linalg, stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.core import identify
from robocal_uncertainty.core.instruments import EncoderNoise, TrackerNoise
from robocal_uncertainty.core.kinematics import forward_points_and_jacobian
from robocal_uncertainty.core.model_error_field import chordal_distance, kernel_correlation
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.core.session import parameter_gain
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty.model_adequacy import (
    assess_model_adequacy,
    pose_noise_covariances,
)
from robocal_uncertainty.uncertainty.model_error_draws import estimate_field

SERIES = {
    "D": ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv",
    "B": ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "series_b" / "measurements_joint_configurations.csv",
}


def _correlation(q_a: np.ndarray, q_b: np.ndarray, c: float, ell: float, same: bool) -> np.ndarray:
    corr = c * kernel_correlation(chordal_distance(q_a, q_b), ell)
    return corr + (1.0 - c) * np.eye(q_a.shape[0]) if same else corr


def one_split(model, campaign, train: np.ndarray, held: np.ndarray) -> tuple[float, float, float, float, float]:
    tr, ho = campaign.subset(train), campaign.subset(held)
    cal = identify(model, tr)
    q_t, q_c = tr.joint_positions, ho.joint_positions
    tracker, encoder = TrackerNoise(), EncoderNoise()
    dist_t = np.linalg.norm(tr.points, axis=1)
    adequacy = assess_model_adequacy(cal, q_t, tracker, encoder, dist_t)
    noise = pose_noise_covariances(cal, q_t, tracker, encoder, dist_t)
    est = estimate_field(cal, q_t, noise, adequacy.residual_covariance)
    s_m, c, ell = est.per_pose_covariance, est.correlated_fraction, est.length_scale
    layout = cal.model.layout
    names = [i for i, e in enumerate(cal.estimated) if e]
    gain = parameter_gain(cal, q_t)  # (k, 3 n_t), measurement frame
    _, jac_t = forward_points_and_jacobian(layout, cal.estimate, q_t)
    pred_c, jac_c = forward_points_and_jacobian(layout, cal.estimate, q_c)
    a_mat = jac_t[:, :, names].reshape(-1, len(names))
    j_c = jac_c[:, :, names].reshape(-1, len(names))
    k_tt = np.kron(_correlation(q_t, q_t, c, ell, True), s_m) + linalg.block_diag(*noise)
    k_ct = np.kron(_correlation(q_c, q_t, c, ell, False), s_m)
    k_cc_diag = np.kron(np.eye(q_c.shape[0]), s_m)  # per-configuration blocks only
    # Contrasts z = Q^T r (Q orthonormal, orthogonal to the fit's Jacobian): Q^T r = Q^T (e + eps),
    # whatever the parameters; what the residuals carry about the field is in them.
    u_full = np.linalg.svd(a_mat, full_matrices=True)[0]
    q_mat = u_full[:, np.linalg.matrix_rank(a_mat) :]
    cov_z = q_mat.T @ k_tt @ q_mat
    cross = (k_ct - j_c @ gain @ k_tt) @ q_mat  # Cov(delta_c, z)
    z_t = q_mat.T @ np.asarray(cal.residuals).reshape(-1)
    pinv = np.linalg.inv(cov_z)
    correction = (cross @ pinv @ z_t).reshape(-1, 3)
    y = ho.points
    err_plain = y - pred_c
    err_krig = err_plain - correction
    # Variance of delta_c per configuration (blocks), before and after conditioning on r_t.
    jg = j_c @ gain
    var_delta = (
        np.einsum("ij,ji->i", k_cc_diag, np.eye(k_cc_diag.shape[0]))
        + np.einsum("ij,jk,ik->i", jg, k_tt, jg)
        - 2.0 * np.einsum("ij,ij->i", jg, k_ct)
    )
    var_krig = var_delta - np.einsum("ij,jk,ik->i", cross, pinv, cross)
    var_krig = np.clip(var_krig, 0.0, None) + (tracker.std(np.linalg.norm(y, axis=1)) ** 2).repeat(3)
    z = err_krig.reshape(-1) / np.sqrt(var_krig)
    inside = float(np.mean(np.abs(z) <= stats.norm.ppf(0.975)))
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e**2, axis=1))))  # noqa: E731
    return rms(err_plain), rms(err_krig), inside, c, ell


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
            a = np.array(rows)
            print(
                f"series {name} ({campaign.n_poses} poses), {n_train} training: held-out 3-D RMS "
                f"{a[:, 0].mean() * 1e3:.3f} mm -> {a[:, 1].mean() * 1e3:.3f} mm with the field's conditional mean "
                f"({(a[:, 1].mean() / a[:, 0].mean() - 1) * 100:+.1f} %), inside 95 % (kriging variance, per axis) "
                f"{a[:, 2].mean() * 100:.1f} %, c {a[:, 3].mean():.2f}, l {a[:, 4].mean():.2f} rad",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
