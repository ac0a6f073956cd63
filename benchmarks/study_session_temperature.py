"""Is the temperature the UR10 series record a useful term of the between-session model?

Both real series (B, November 2020; D, March 2021) record the air temperature at every pose.
A warmer robot has longer links: the ``length_scale`` session effect (every ``a`` and ``d``
scaled by ``1 + s``) with ``s = k (T - T_ref)``. This fits, on every pose of each series, the
calibrated model's prediction with the tracker pose and tool point re-registered (ordinary
least squares) and a thermal coefficient ``k`` [ppm/K] on the poses' temperature differences,
and sets the fitted ``k`` and the temperature difference between the series against the
length-scale change between the sessions and the aluminium links' 23 ppm/K.

    python benchmarks/study_session_temperature.py

The calibration is of every pose of series D (``identify``, ``lambda`` auto). The stated
standard deviations treat the residuals as independent (they are not: the model error is
correlated over the poses), so they are lower bounds.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.core import identify, load_robot_model
from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import fit_rigid_base
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.session import BASE_NAMES, LENGTH_SCALE, TOOL_NAMES, effect_jacobian
from robocal_uncertainty.importers import read_tracker_csv

SERIES = {
    "D": ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv",
    "B": ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "series_b" / "measurements_joint_configurations.csv",
}
ALUMINIUM_PPM_PER_K = 23.0


def temperatures(path: Path) -> np.ndarray:
    """The ``measurement_temperature`` column [deg C], one per pose, file order."""
    lines = path.read_text().splitlines()
    head = lines[0].split(";")
    col = head.index("measurement_temperature")
    return np.array([float(line.split(";")[col].replace(",", ".")) for line in lines[1:] if line.strip()])


def fit(model: RobotModel, campaign: Campaign, dt: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, float]:
    """OLS of tracker pose, tool point and the effects (length scale, and ``k`` on `dt` when given):
    the effects [1, 1/K], their standard deviations and the RMS residual [m]."""
    layout = model.layout
    campaign = campaign.reorder_joints(model.joint_names)
    y = np.asarray(campaign.measurement.positions(campaign.points), dtype=np.float64)
    q = campaign.joint_positions
    p = model.parameter_vector()
    b0 = layout.base_index
    p_kin = p.copy()
    p_kin[b0 : b0 + 6] = 0.0
    xyz, rpy = fit_rigid_base(forward_points(layout, p_kin, q), y)
    p[b0 : b0 + 3], p[b0 + 3 : b0 + 6] = xyz, rpy
    free = np.array([layout.names.index(n) for n in (*BASE_NAMES, *TOOL_NAMES)])
    effects = np.zeros(2 if dt is not None else 1)
    for _ in range(20):
        pred, jac = forward_points_and_jacobian(layout, p, q)
        g = effect_jacobian(layout, p, q, (LENGTH_SCALE,))[:, :, 0]
        cols = [g.reshape(-1)]
        if dt is not None:
            cols.append((g * dt[:, None]).reshape(-1))
        a = np.concatenate((jac[:, :, free].reshape(-1, free.size), np.stack(cols, axis=1)), axis=1)
        model_pred = pred.reshape(-1) + np.stack(cols, axis=1) @ effects
        step = np.linalg.lstsq(a, y.reshape(-1) - model_pred, rcond=None)[0]
        p[free] += step[: free.size]
        effects = effects + step[free.size :]
        if np.max(np.abs(step[: free.size])) < 1e-12:
            break
    r = y.reshape(-1) - model_pred - a @ step
    sigma2 = float(r @ r) / (r.size - a.shape[1])
    cov = sigma2 * np.linalg.pinv(a.T @ a)
    std = np.sqrt(np.diag(cov))[free.size :]
    return effects, std, float(np.sqrt(np.mean(r.reshape(-1, 3) ** 2) * 3))


def main() -> None:
    model = load_robot_model(ROOT / "robocal_uncertainty" / "data" / "ur10.yaml")
    series = {name: read_tracker_csv(path) for name, path in SERIES.items()}
    temps = {name: temperatures(path) for name, path in SERIES.items()}
    for name, campaign in series.items():
        t = temps[name]
        assert t.size == campaign.n_poses, (name, t.size, campaign.n_poses)
        print(
            f"series {name}: {t.size} poses, temperature {t.mean():.2f} deg C "
            f"(sd {t.std():.2f}, range {t.min():.2f}-{t.max():.2f})"
        )
    cal = identify(model, series["D"], lambda_="auto", accept_unconverged=True)
    calibrated = cal.model
    print("calibrated on every pose of D")
    ref_t = float(temps["D"].mean())
    for name in ("D", "B"):
        dt = temps[name] - temps[name].mean()
        (scale,), (scale_sd,), rms0 = fit(calibrated, series[name], None)
        (_, k), (_, k_sd), rms1 = fit(calibrated, series[name], dt)
        print(
            f"  {name}: length scale against D's calibration {scale * 1e6:+.1f} +- {scale_sd * 1e6:.1f} ppm "
            f"(mean temperature {temps[name].mean() - ref_t:+.2f} K from D's: aluminium would give "
            f"{ALUMINIUM_PPM_PER_K * (temps[name].mean() - ref_t):+.1f} ppm); within the series k = "
            f"{k * 1e6:+.1f} +- {k_sd * 1e6:.1f} ppm/K; RMS {rms0 * 1e3:.4f} mm without, {rms1 * 1e3:.4f} mm with "
            f"the thermal term"
        )


if __name__ == "__main__":
    main()
