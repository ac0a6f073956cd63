"""The chain walk two ways: joint by joint over the poses (the kernel's) against pose by pose.

The compiled walk (:func:`~robocal_uncertainty.kernels._numba_walk.walk`) takes a trial's
poses joint by joint: every loop runs over contiguous arrays of the poses, which the compiler
vectorises. The other way, the one a prototype of the issue took, walks each pose's chain
from the tool to the base with the point in registers and no array per trial; it is written
here with the kernel's operations in the kernel's order (the same cosine and sine of every
angle, the same turns), so the two give the same values to the bit, which is checked.

Both run on one thread on the same trials (the point at every pose, a simulated campaign of
the robot reference paper's arm, 53 and 632 poses, 256 trials whose readings differ by up to
1e-4 rad from the reference), in CPU seconds of this process, best of ``--repeats``.
Nothing here is a pass/fail test; on a shared machine, take the ratio, not the times.

Usage: python benchmarks/bench_walk_layouts.py [--repeats 20]
"""

from __future__ import annotations

import os
import sys

os.environ["NUMBA_NUM_THREADS"] = "1"
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import time
from functools import partial
from pathlib import Path

import numba
import numpy as np

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.kernels._numba_walk import _cos_sin, _rpy, walk
from robocal_uncertainty.kernels.predictors import CompiledPredictor

ROOT = Path(__file__).resolve().parents[1]


@numba.njit(error_model="numpy")
def walk_by_pose(
    params: np.ndarray,
    qs: np.ndarray,
    walker: tuple[np.ndarray, ...],
    reference: tuple[np.ndarray, np.ndarray, np.ndarray],
    out: np.ndarray,
) -> None:
    """Tool points (n_trials, n_poses, 3), each pose's chain walked with the point in registers
    (the arguments as for :func:`walk`, points only; `walker` is ``joints .. sin_ref``,
    `reference` ``p_ref, cos_p, sin_p``)."""
    joints, blocks, q_ref, theta_ref, cos_ref, sin_ref = walker
    p_ref, cos_p, sin_p = reference
    n_trials, n_poses = out.shape[0], out.shape[1]
    nj = joints.shape[0]
    t0, m0, b0 = blocks[0], blocks[2], blocks[3]
    rot = np.empty(27)
    link = np.empty((nj, 8))
    for t in range(n_trials):
        p = params[t]
        q = qs[t]
        _rpy(p, b0 + 3, p_ref, cos_p, sin_p, rot[0:9])
        if m0 >= 0:
            _rpy(p, m0 + 3, p_ref, cos_p, sin_p, rot[9:18])
        for j in range(nj):
            ca, sa = _cos_sin(
                p[joints[j, 0]] - p_ref[joints[j, 0]], cos_p[joints[j, 0]], sin_p[joints[j, 0]], p[joints[j, 0]]
            )
            cb, sb = 1.0, 0.0
            if joints[j, 4] >= 0:
                k = joints[j, 4]
                cb, sb = _cos_sin(p[k] - p_ref[k], cos_p[k], sin_p[k], p[k])
            theta = p[joints[j, 2]]
            link[j, 0] = p[joints[j, 3]]
            link[j, 1] = p[joints[j, 1]]
            link[j, 2], link[j, 3], link[j, 4], link[j, 5] = ca, sa, cb, sb
            link[j, 6] = theta - theta_ref[j]
            link[j, 7] = theta
        for i in range(n_poses):
            x, y, z = p[t0], p[t0 + 1], p[t0 + 2]
            for j in range(nj - 1, -1, -1):
                d, a, ca, sa, cb, sb, dtheta, theta = link[j]
                if joints[j, 5] != 0:
                    z = z + (d + q[i, j])
                    change, angle = dtheta, theta
                else:
                    z = z + d
                    change, angle = (q[i, j] - q_ref[j, i]) + dtheta, q[i, j] + theta
                c, s = _cos_sin(change, cos_ref[j, i], sin_ref[j, i], angle)
                x, y = c * x - s * y, s * x + c * y
                if joints[j, 4] >= 0:
                    z, x = cb * z - sb * x, sb * z + cb * x
                y, z = ca * y - sa * z, sa * y + ca * z
                x = x + a
            if m0 >= 0:
                x, y, z = (
                    rot[9] * x + rot[10] * y + rot[11] * z + p[m0],
                    rot[12] * x + rot[13] * y + rot[14] * z + p[m0 + 1],
                    rot[15] * x + rot[16] * y + rot[17] * z + p[m0 + 2],
                )
            for r in range(3):
                out[t, i, r] = rot[3 * r] * x + rot[3 * r + 1] * y + rot[3 * r + 2] * z + p[b0 + r]


def _best(run: partial[None], repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        run()
        best = min(best, time.process_time() - start)
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    n = 256
    print(f"{'poses':>5}{'by joint, us':>14}{'by pose, us':>13}{'by pose / by joint':>20}  same values")
    for n_poses in (53, 632):
        campaign = simulate_campaign(model, SimulationSettings(n_poses=n_poses), seed=1).campaign
        calibration = identify(model, campaign)
        ref = CompiledPredictor.at(calibration.model.layout, calibration.estimate, campaign.joint_positions)
        rng = np.random.default_rng(0)
        q = np.ascontiguousarray(
            campaign.joint_positions + rng.uniform(-1e-4, 1e-4, (n, *campaign.joint_positions.shape))
        )
        params = np.ascontiguousarray(np.repeat(calibration.estimate[None], n, axis=0))
        flat = ref.flat
        common = (q, flat.joints, flat.blocks, ref.reference_readings, ref.theta, ref.cos_ref, ref.sin_ref)
        by_joint = np.empty((n, n_poses, 3))
        by_pose = np.empty((n, n_poses, 3))

        joint_major = partial(walk, params, *common, *ref.parameter_trig, False, by_joint, 1)
        pose_major = partial(walk_by_pose, params, q, common[1:], ref.parameter_trig, by_pose)
        joint_major()
        pose_major()
        same = bool(np.array_equal(by_joint, by_pose))
        t_joint = _best(joint_major, args.repeats) / n
        t_pose = _best(pose_major, args.repeats) / n
        print(f"{n_poses:>5}{t_joint * 1e6:>14.2f}{t_pose * 1e6:>13.2f}{t_pose / t_joint:>19.2f}x  {same}")
    print(f"load average: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
