"""Series D: how far the uncompensated UR10 missed its commanded targets, and the predicted miss
after compensation with its stated interval, on held-out targets.

The series records, per pose, the commanded T-Mac pose (``Goal x/y/z`` [m], ``Goal
roll/pitch/yaw`` [rad], in the controller's base frame), the joints the controller chose for
it with its own factory kinematics, and where the T-Mac went (tracker). What this prints:

1. The goals' orientation convention, established against the kinematics (the angle between
   two poses' rotations does not depend on the unknown base and tool rotations, so it must
   equal the nominal UR10's at the recorded joints): ``extrinsic_xyz`` (ROS roll, pitch, yaw,
   ``Rz(yaw) Ry(pitch) Rx(roll)``) against the others.
2. The split of ``validate --train-poses N --seed S`` (the same function, the same seed):
   calibration on N poses, the other poses held out.
3. Before: the commanded positions registered into the tracker frame by a rigid fit on the
   training poses only, and the measured miss of the held-out targets.
4. Compensation of the held-out targets (registered goals, tracker frame) under the calibration
   of the training poses, seeded with the controller's joints: joints, FK error, refusals, and
   the stated uncertainty of the reached position (the Monte Carlo of ``evaluate``).
5. After (predicted): the compensated robot lands where the calibrated model's prediction error
   puts it; its size on the held-out poses is what ``validate`` measures on the same split
   (measured minus predicted at the recorded joints, a few mrad from the compensated ones), and
   the coverage of the compensated targets' stated intervals is counted on those errors.

    python benchmarks/series_d_compensation.py                    # 53 training poses, seed 0
    python benchmarks/series_d_compensation.py --seed 1 --trials 2000

Run time: about 3 minutes on two cores (two Monte Carlo runs of 5000 trials at 579 poses).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from robocal_uncertainty.app.compensation import compensate
from robocal_uncertainty.app.validation import validate
from robocal_uncertainty.core.calibration_file import calibration_to_dict
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.kinematics import forward_poses
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model, resolve_robot_config
from robocal_uncertainty.core.rotation import EULER_CONVENTIONS, euler_to_matrix, rotation_log
from robocal_uncertainty.importers.targets import Targets
from robocal_uncertainty.importers.tracker_csv import read_tracker_csv
from robocal_uncertainty.uncertainty import EvaluationSettings, UncertaintySettings
from robocal_uncertainty.uncertainty.holdout import split_campaign

CSV = ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"
SOURCES = ("tracker", "encoder", "residual")


def read_goals(path: Path, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Goal positions [m] and roll, pitch, yaw [rad] of the campaign's source rows."""
    lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    header = lines[0].split(";")
    data = np.array([[float(c.replace(",", ".")) for c in line.split(";")] for line in lines[1:]])[rows]
    xyz = data[:, [header.index(f"Goal {a}") for a in "xyz"]]
    rpy = data[:, [header.index(f"Goal {a}") for a in ("roll", "pitch", "yaw")]]
    return xyz, rpy


def relative_angle_rms(model_rotations: np.ndarray, rotations: np.ndarray, seed: int = 0) -> float:
    """RMS difference [rad] of the angles between 3000 random pose pairs (invariant to the
    unknown constant rotations on either side)."""
    i, j = np.random.default_rng(seed).integers(0, rotations.shape[0], (2, 3000))

    def rel(r: np.ndarray) -> np.ndarray:
        return np.linalg.norm(rotation_log(np.swapaxes(r[i], -1, -2) @ r[j]), axis=-1)

    return float(np.sqrt(np.mean((rel(rotations) - rel(model_rotations)) ** 2)))


def rigid_fit(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising |R source + t - target| (Kabsch)."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    u, _, vt = np.linalg.svd((source - cs).T @ (target - ct))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, ct - rotation @ cs


def stats(errors: np.ndarray) -> str:
    norm = np.linalg.norm(errors, axis=1)
    axes = ", ".join(f"{v * 1e6:.0f}" for v in np.sqrt(np.mean(errors**2, axis=0)))
    return (
        f"3-D RMS {np.sqrt(np.mean(norm**2)) * 1e6:7.0f} um, per axis ({axes}) um, "
        f"95th percentile {np.percentile(norm, 95) * 1e6:.0f} um, max {norm.max() * 1e6:.0f} um"
    )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The study's command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--train-poses", type=int, default=53)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--trials", type=int, default=5000)
    parser.add_argument("--workers", type=int, default=1)
    return parser.parse_args(argv)


def print_conventions(flange: np.ndarray, rpy: np.ndarray) -> None:
    """Which Euler convention the goals' roll/pitch/yaw use: the RMS angle between pose pairs of the
    nominal flange rotations and of the goals read in each convention."""
    print("Goal roll/pitch/yaw convention: RMS difference of the angles between 3000 pose pairs from the nominal")
    print("UR10 at the recorded joints (invariant to the unknown base and tool rotations):")
    for convention in EULER_CONVENTIONS:
        rms = relative_angle_rms(flange, euler_to_matrix(rpy, convention))
        print(f"  {convention:<14} {rms * 1e3:9.3f} mrad")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    t0 = time.perf_counter()
    campaign = read_tracker_csv(CSV)
    model = load_robot_model(resolve_robot_config("ur10"))
    q = campaign.reorder_joints(model.joint_names).joint_positions
    goals, rpy = read_goals(CSV, np.asarray(campaign.metadata["source_rows"], dtype=int))

    _, flange = forward_poses(model, model.parameter_vector(), q)
    print_conventions(flange, rpy)

    split = split_campaign(campaign.n_poses, n_train=args.train_poses, seed=args.seed)[0]
    train, held = split.train, split.held_out
    train_campaign = campaign.subset(train)
    measured = campaign.points
    rotation, translation = rigid_fit(goals[train], measured[train])
    registered = goals @ rotation.T + translation
    fit = registered[train] - measured[train]
    print(
        f"\nSplit of validate --train-poses {args.train_poses} --seed {args.seed}: {train.size} training poses, "
        f"{held.size} held out"
    )
    print(
        f"Commanded frame -> tracker frame: rigid fit on the training poses, residual RMS "
        f"{np.sqrt(np.mean(np.sum(fit**2, axis=1))) * 1e6:.0f} um"
    )
    before = measured[held] - registered[held]
    print(f"\nBEFORE (measured miss of the uncompensated robot, {held.size} held-out targets):")
    print(f"  {stats(before)}")

    calibration = identify(model, train_campaign, lambda_="auto")
    data = calibration_to_dict(calibration, robot="ur10")
    options = EvaluationSettings(
        uncertainty=UncertaintySettings(sources=SOURCES), trials=args.trials, seed=args.seed, coverage=0.95
    )
    targets = Targets(registered[held], None, "Series D Goal x/y/z, registered", "m")
    result = compensate(
        model,
        data,
        targets,
        frame="measurement",
        seeds=q[held],
        campaign=train_campaign,
        options=options,
        workers=args.workers,
    )
    ok = result.accepted
    sol = result.solution
    print(
        f"\nCOMPENSATION of the held-out targets (calibration on the {train.size} training poses, "
        f"residual RMS {calibration.rms_after * 1e6:.0f} um; seeds: the controller's joints):"
    )
    print(
        f"  {int(ok.sum())} of {held.size} compensated; FK error max {sol.position_error_m[ok].max():.2g} m; "
        f"joint corrections median {np.degrees(np.median(sol.joint_change[ok])) * 1e3:.1f} mdeg, "
        f"max {np.degrees(sol.joint_change[ok].max()) * 1e3:.1f} mdeg; reproduction {result.reproduction_m:.2g} m"
    )
    for i in np.flatnonzero(~ok):
        seed = " ".join(f"{v:.4f}" for v in q[held][i])
        print(f"  target {i + 1}: {result.status[i]}; seed joints {seed} rad")
    unc = result.uncertainty
    assert unc is not None
    u = np.array([[a.standard_uncertainty for a in p.axes] for p in unc.poses])
    lo = np.array([[a.interval.low for a in p.axes] for p in unc.poses])
    hi = np.array([[a.interval.high for a in p.axes] for p in unc.poses])
    means = np.array([p.mean for p in unc.poses])
    med = ", ".join(f"{v * 1e6:.0f}" for v in np.median(u, axis=0))
    big = ", ".join(f"{v * 1e6:.0f}" for v in np.median((hi - lo) / 2, axis=0))
    print(
        f"  stated ({unc.n_trials} trials, seed {unc.seed}, sources {','.join(unc.settings.sources)}): "
        f"median u = ({med}) um, median 95 % half-width ({big}) um"
    )

    validation = validate(model, campaign, options, train_poses=args.train_poses)
    errors = validation.errors  # measured minus predicted at the recorded joints, held-out order
    print("\nAFTER (predicted miss of the compensated robot = the calibrated model's held-out prediction error,")
    print(f"what validate --train-poses {args.train_poses} --seed {args.seed} --trials {args.trials} measures):")
    print(f"  {stats(errors)}")
    axes = ", ".join(f"{100 * a.inside_fraction:.1f}" for a in validation.axes)
    region = 100 * validation.region_inside_fraction
    print(f"  validate: inside its 95 % intervals ({axes}) % per axis, {region:.1f} % inside the 3-D region")
    # The compensated targets' stated intervals, centred on their Monte Carlo mean, applied to
    # those errors: how often the miss lies inside the interval stated for the compensated move.
    landing = means + errors[ok]
    inside = (landing >= lo) & (landing <= hi)
    cov = ", ".join(f"{100 * v:.1f}" for v in inside.mean(axis=0))
    print(f"  compensated targets' stated 95 % intervals hold the held-out miss: ({cov}) % per axis")
    rms_before = float(np.sqrt(np.mean(np.sum(before**2, axis=1))))
    rms_after = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
    print(
        f"\nImprovement (3-D RMS): {rms_before * 1e6:.0f} um -> {rms_after * 1e6:.0f} um "
        f"(x {rms_before / rms_after:.2f}); {time.perf_counter() - t0:.0f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
