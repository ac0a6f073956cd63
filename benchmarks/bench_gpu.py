"""The CuPy backend on a GPU: one short prepared script (a few minutes), for when a GPU is lent.

What it measures, each against the numpy backend in the same run:
1. equality: the GPU walk (points and 6-DOF poses) against ``forward_points`` /
   ``forward_poses`` on the CPU, and whole trial blocks of the ``cupy`` backend against the
   ``numpy`` backend from the same draws (600 trials, 53 poses; points and 6-DOF), to 1e-12;
2. the walk alone on the device, inputs already there (no transfer): 10^6 trials x 53 poses
   and 10^5 x 632, points and poses, float64, synchronised; and the same with the host
   transfers the backend does today (parameters and readings in, values out);
3. whole trial blocks (``run_trials``, start-up excluded): numpy, cupy, and numba (1 thread)
   when installed, at 53 and 632 poses, so the share the walk has in a trial is visible.

What it does not measure: 10^6 *calibration trials* on the GPU. The backend moves the walk to
the device; the draws and the chord solve stay on the host (numpy), so a trial's time there
is bounded by those. Item 2 says what the device gives for the walk.

``--module numpy`` runs everything with numpy standing in for CuPy (a dry run on any machine,
how CI checks the code path); the timings then mean nothing for a GPU.

Usage: python benchmarks/bench_gpu.py [--module cupy|numpy] [--quick]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.core.kinematics import forward_points, forward_poses
from robocal_uncertainty.core.pose_measurement import pose_values
from robocal_uncertainty.kernels import CupyBackend, NumbaBackend, register_backend
from robocal_uncertainty.kernels._layout import flat_layout
from robocal_uncertainty.kernels._walk_xp import walk_xp
from robocal_uncertainty.kernels.predictors import ArrayModulePredictor
from robocal_uncertainty.montecarlo.engine import run_trials
from robocal_uncertainty.uncertainty import UncertaintySettings, prepare_calibration_trials

ROOT = Path(__file__).resolve().parents[1]
TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])


def _sync(xp: object) -> None:
    cuda = getattr(xp, "cuda", None)
    if cuda is not None:
        cuda.Stream.null.synchronize()


def check_walk(module: str, model: object) -> None:
    layout = model.layout  # type: ignore[attr-defined]
    rng = np.random.default_rng(0)
    p0 = model.parameter_vector()  # type: ignore[attr-defined]
    q0 = rng.uniform(-2.0, 2.0, (53, layout.n_joints))
    predictor = ArrayModulePredictor.on(module, layout, p0, q0)
    p = p0 + rng.normal(0.0, 1e-6, (100, layout.size))
    q = q0 + rng.normal(0.0, 1e-5, (100, *q0.shape))
    err_points = np.abs(predictor(p, q) - forward_points(layout, p, q)).max()
    err_poses = np.abs(predictor.poses(p, q) - pose_values(*forward_poses(layout, p, q))).max()
    print(f"walk vs forward kinematics (CPU): points {err_points:.1e} m, poses {err_poses:.1e} (m, -)")


def check_blocks(model: object) -> None:
    for orientation in (None, float(np.radians(0.01))):
        campaign = simulate_campaign(model, SimulationSettings(orientation_std=orientation), seed=1).campaign  # type: ignore[arg-type]
        calibration = identify(model, campaign)  # type: ignore[arg-type]
        sources = ("tracker", "encoder") + (("tracker_orientation",) if orientation else ())
        settings = UncertaintySettings(sources=sources)
        blocks = [
            run_trials(
                prepare_calibration_trials(
                    model,  # type: ignore[arg-type]
                    campaign,
                    TEST_JOINTS,
                    settings=settings,
                    calibration=calibration,
                    backend=name,
                ),
                seed=0,
                n_trials=600,
            ).samples
            for name in ("numpy", "cupy")
        ]
        rel = (np.abs(blocks[1] - blocks[0]).max(axis=0) / np.maximum(np.abs(blocks[0]).max(axis=0), 1.0)).max()
        print(f"trial blocks cupy vs numpy ({'6-DOF' if orientation else 'point'}): {rel:.1e} relative")


def time_walk(module: str, model: object, n_trials: int, n_poses: int) -> None:
    xp = __import__(module)
    layout = model.layout  # type: ignore[attr-defined]
    rng = np.random.default_rng(1)
    p0 = model.parameter_vector()  # type: ignore[attr-defined]
    q0 = rng.uniform(-2.0, 2.0, (n_poses, layout.n_joints))
    predictor = ArrayModulePredictor.on(module, layout, p0, q0)
    p_host = p0 + rng.normal(0.0, 1e-6, (n_trials, layout.size))
    q_host = q0 + rng.normal(0.0, 1e-5, (n_trials, n_poses, layout.n_joints))
    flat = flat_layout(layout)
    reference = tuple(xp.asarray(a) for a in (q0.T, predictor.theta, predictor.cos_ref, predictor.sin_ref))
    p_dev, q_dev = xp.asarray(p_host), xp.asarray(q_host)
    for poses in (False, True):
        walk_xp(xp, flat, p_dev, q_dev, reference, poses=poses)  # warm-up (kernel compilation)
        _sync(xp)
        best = np.inf
        for _ in range(3):
            start = time.perf_counter()
            walk_xp(xp, flat, p_dev, q_dev, reference, poses=poses)
            _sync(xp)
            best = min(best, time.perf_counter() - start)
        start = time.perf_counter()
        (predictor.poses if poses else predictor)(p_host, q_host)
        with_transfer = time.perf_counter() - start
        print(
            f"walk, {n_trials} trials x {n_poses} poses, {'poses ' if poses else 'points'}: {best:.4f} s on the "
            f"device ({n_trials / best:.3g} trials/s), {with_transfer:.3f} s with the host transfers"
        )


def time_blocks(model: object, n_poses: int, n_trials: int) -> None:
    campaign = simulate_campaign(model, SimulationSettings(n_poses=n_poses), seed=1).campaign  # type: ignore[arg-type]
    calibration = identify(model, campaign)  # type: ignore[arg-type]
    settings = UncertaintySettings(sources=("tracker", "encoder"))
    names = ["numpy", "cupy"] + (["numba"] if NumbaBackend().available() else [])
    base = None
    for name in names:
        trials = prepare_calibration_trials(
            model,  # type: ignore[arg-type]
            campaign,
            TEST_JOINTS,
            settings=settings,
            calibration=calibration,
            backend=name,
        )
        run_trials(trials, seed=0, n_trials=min(n_trials, 1000))
        start = time.perf_counter()
        run_trials(trials, seed=0, n_trials=n_trials)
        elapsed = (time.perf_counter() - start) / n_trials
        base = base or elapsed
        print(f"trial blocks, {n_poses} poses, {name}: {elapsed * 1e6:.1f} us/trial wall ({base / elapsed:.2f}x numpy)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--module", default="cupy", choices=("cupy", "numpy"))
    parser.add_argument("--quick", action="store_true", help="1000x fewer trials (a dry run of the code paths)")
    args = parser.parse_args()
    xp = __import__(args.module)
    register_backend(CupyBackend(module=args.module))
    if args.module == "cupy":
        props = xp.cuda.runtime.getDeviceProperties(0)
        print(f"GPU: {props['name'].decode()}, CuPy {xp.__version__}")
    else:
        print("numpy standing in for CuPy: a dry run, the timings are not a GPU's")
    scale = 1000 if args.quick else 1
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    check_walk(args.module, model)
    check_blocks(model)
    time_walk(args.module, model, 1_000_000 // scale, 53)
    time_walk(args.module, model, 100_000 // scale, 632)
    time_blocks(model, 53, max(300, 20_000 // scale))
    time_blocks(model, 632, max(300, 2_000 // scale))
    return 0


if __name__ == "__main__":
    sys.exit(main())
