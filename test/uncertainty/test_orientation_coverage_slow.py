"""Orientation coverage that is honest: over many simulated 6-DOF campaigns where the model is
right (tracker position and orientation noise, encoder noise), the 95 % intervals of each
rotation axis contain the true tool orientation ~95 % of the time.

Measured (200 campaigns x 3 test configurations, 400 trials each, sources tracker,
tracker_orientation, encoder; orientation noise 0.1 mrad): paper arm (base frame) rx 94.2 %,
ry 94.3 %, rz 96.0 %, positions x 95.3 %, y 95.2 %, z 95.8 %, region 95.2 %; UR10 (tracker
frame, identified base) rx 95.7 %, ry 94.0 %, rz 94.5 %, x 95.2 %, y 93.2 %, z 95.8 %, region
92.7 %. Points only, tool point 80 mm off joint 6's axis (the rotation about it undetermined):
the tilt perpendicular to it 93.2 % and 94.8 %. Points only with the shipped tool points (on
the axis): the "determined" tilt holds the truth in only 2-8 %, see
``test_point_orientation_truth.py``. Run times here (shared 2-core machine): 89 s, 44 s, 10 s.

Slow: ``python -m pytest -m slow test/uncertainty/test_orientation_coverage_slow.py -s``.
Also runnable as a script: ``python test/uncertainty/test_orientation_coverage_slow.py [n_campaigns]``.
"""

from __future__ import annotations

import dataclasses
import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.core.kinematics import forward_poses
from robocal_uncertainty.core.rotation import rotation_exp, rotation_log
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty

ROOT = Path(__file__).resolve().parents[2]

# Three configurations spread over the workspace (the first is the seed's test pose).
TEST_JOINTS = {
    "paper_arm": np.radians(
        [
            [-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451],
            [10.0, -200.0, -90.0, -80.0, -50.0, 30.0],
            [60.0, -120.0, -60.0, 30.0, 80.0, -90.0],
        ]
    ),
    "ur10": np.array(
        [
            [0.934319, -1.79251, 1.5196, 0.272862, 0.934269, -1.57075],
            [0.3, -1.2, 1.1, 0.2, 0.5, 0.1],
            [-1.0, -2.0, -1.3, 1.0, -0.7, 2.0],
        ]
    ),
}
# The paper arm's campaign in its base frame; the UR10's in the tracker frame (its base unknown,
# identified from the data, so the output orientation carries the base's uncertainty too).
FRAMES = {"paper_arm": "base", "ur10": "tracker"}
ORIENTATION_STD = 1e-4  # [rad] per axis: a 6-DOF probe's ~0.1 mrad
SOURCES_6DOF = ("tracker", "tracker_orientation", "encoder")
OFF_AXIS_TOOL = (0.08, 0.0, 0.05)  # [m] in the flange frame
KEYS = ("rx", "ry", "rz", "x", "y", "z", "region")


def coverage_experiment(
    robot: str,
    n_campaigns: int,
    *,
    trials: int = 400,
    seed: int = 2025,
    orientation_std: float | None = ORIENTATION_STD,
    tool_point: tuple[float, float, float] | None = None,
) -> dict[str, float]:
    """Fraction of (campaign, test configuration) pairs whose 95 % intervals hold the truth.

    Rotation axes: the truth is expressed as the result states its deviations, a rotation vector
    about the fixed axes of the output frame taken from the Monte Carlo mean,
    ``log(R_true R_mean^T)``, compared with each axis' probabilistically symmetric interval.
    Positions: each coordinate's interval and the 3-D region, for reference.

    With ``orientation_std=None`` the campaigns hold points only; the rotation about the
    undetermined directions is then unknown and only the tilt perpendicular to them is
    checked (``perp1``, ``perp2`` where that plane is two-dimensional), with intervals taken
    from the trials' deviations projected on it.
    """
    model = load_robot_model(ROOT / "config" / f"{robot}.yaml")
    if tool_point is not None:
        model = dataclasses.replace(model, tool_point=np.asarray(tool_point, dtype=np.float64))
    test_q = TEST_JOINTS[robot]
    settings = SimulationSettings(frame=FRAMES[robot], orientation_std=orientation_std)  # type: ignore[arg-type]
    sources = SOURCES_6DOF if orientation_std is not None else ("tracker", "encoder")
    unc = UncertaintySettings(sources=sources)
    rng = np.random.default_rng(seed)
    hits = dict.fromkeys(KEYS, 0)
    perp_hits = [0, 0]
    perp_n = [0, 0]
    n = 0
    n_undetermined = 0
    for i in range(n_campaigns):
        sim = simulate_campaign(model, settings, rng=np.random.default_rng(rng.integers(2**63)))
        # The arm asked to go to the test joints sits within the encoder error of them.
        q_true = test_q + settings.encoder_noise.sample(rng, test_q.shape)
        p_true, r_true = forward_poses(sim.true_model, sim.true_model.parameter_vector(), q_true)
        result = evaluate_uncertainty(model, sim.campaign, test_q, uncertainty=unc, trials=trials, seed=i)
        for k, pose in enumerate(result.poses):
            o = pose.orientation
            assert o is not None
            n += 1
            delta = rotation_log(r_true[k] @ o.mean_rotation.T)
            for j, axis in enumerate(("x", "y", "z")):
                hits[axis] += pose.axes[j].probabilistically_symmetric.contains(float(p_true[k, j]))
            hits["region"] += bool(pose.region is not None and pose.region.contains(p_true[k]))
            if orientation_std is not None:
                assert o.fully_determined
                for j, axis in enumerate(("rx", "ry", "rz")):
                    hits[axis] += o.axes[j].probabilistically_symmetric.contains(float(delta[j]))
                continue
            # Points only: check the deviation in the plane perpendicular to the undetermined axes.
            u = o.undetermined_directions
            n_undetermined += u.shape[0]
            _, _, vt = np.linalg.svd(u, full_matrices=True)
            perp = vt[u.shape[0] :]
            assert result.rotation_samples is not None
            raw = result.rotation_samples[:, 3 * k : 3 * k + 3]
            # Trial rotations exp(raw) R_cal, as deviations about the mean like the result's.
            dev = rotation_log(rotation_exp(raw) @ (o.calibrated_rotation @ o.mean_rotation.T))
            for m, e in enumerate(perp):
                lo, hi = np.quantile(dev @ e, [0.025, 0.975])
                perp_hits[m] += bool(lo <= float(delta @ e) <= hi)
                perp_n[m] += 1
    out = {key: hits[key] / n for key in KEYS if orientation_std is not None or key not in ("rx", "ry", "rz")}
    for m in range(2):
        if perp_n[m]:
            out[f"perp{m + 1}"] = perp_hits[m] / perp_n[m]
    out["undetermined_per_pair"] = n_undetermined / n
    out["n_campaigns"] = float(n_campaigns)
    out["n_pairs"] = float(n)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["paper_arm", "ur10"])
def test_95_percent_rotation_intervals_cover_the_true_orientation(robot: str) -> None:
    cover = coverage_experiment(robot, 200)
    print(robot, cover)
    # 200 campaigns x 3 configurations; the issue asks for 95 % +- 3 % per axis.
    for key in ("rx", "ry", "rz", "x", "y", "z"):
        assert 0.92 <= cover[key] <= 0.98, (key, cover)
    # The 3-D region from 400 trials (its shape estimated too) runs ~1 % under.
    assert 0.90 <= cover["region"] <= 0.98, cover
    assert cover["undetermined_per_pair"] == 0.0


@pytest.mark.slow
def test_point_campaign_tilt_intervals_cover_the_true_orientation() -> None:
    """Points only, tool point 80 mm off joint 6's axis: the rotation about that axis is
    undetermined (one direction per configuration); the tilt perpendicular to it is covered."""
    cover = coverage_experiment("paper_arm", 200, orientation_std=None, tool_point=OFF_AXIS_TOOL)
    print(cover)
    assert cover["undetermined_per_pair"] == 1.0
    for key in ("perp1", "perp2", "x", "y", "z"):
        assert 0.92 <= cover[key] <= 0.98, (key, cover)


if __name__ == "__main__":
    import time

    n_arg = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    for name in TEST_JOINTS:
        t0 = time.perf_counter()
        print(name, coverage_experiment(name, n_arg), f"{time.perf_counter() - t0:.1f} s")
    for name, tool in (("paper_arm", OFF_AXIS_TOOL), ("paper_arm", None), ("ur10", None)):
        t0 = time.perf_counter()
        cover = coverage_experiment(name, n_arg, orientation_std=None, tool_point=tool)
        print(name, tool, "points only", cover, f"{time.perf_counter() - t0:.1f} s")
