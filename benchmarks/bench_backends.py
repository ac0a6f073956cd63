"""Trial kernels: the numba backend against the numpy backend, measured in the same run.

Every case runs the same trial blocks (``run_trials`` on prepared trials, start-up excluded)
from the same draws with each backend:
- point trials: a simulated campaign of the seed's arm, 53 and 632 poses, tracker and encoder
  noise; 6-DOF trials: the same campaigns measured as poses (orientation noise 0.01 deg),
  tracker, encoder and tracker_orientation;
- numpy; numba on 1 thread; numba on all of numba's threads (``NUMBA_NUM_THREADS``);
- per trial: everything, the sources' random draws alone (identical for every backend: the
  part no kernel can remove without changing the random streams), the rest (applying the
  draws, the re-identification and the test configuration), and the re-identification alone
  (``solver.solve`` on one sub-batch of the block's perturbed inputs: what the kernel
  replaces), with the ratios against numpy;
- the chain walk alone: one kinematics pass of the re-identification for 256 trials;
- the ceiling the draws leave: numpy's time per trial over the draws' alone (what a backend
  whose kernel cost nothing would reach; the draws must stay the same values).
With ``--series-d N``: :func:`evaluate_uncertainty` of the shipped UR10 series D (632 poses,
default sources tracker, encoder, residual; orientation; the README's test joints), N trials,
preparation and summaries included (no budget, no sweeps), per backend.

Timings on one thread are CPU seconds of this process (on a shared machine the wall clock
mostly measures the wait for a core); with several threads, wall-clock seconds (CPU seconds
add up the threads), so compare those only on an idle machine. Nothing here is a pass/fail
test. The numba kernel is compiled (or loaded from its disk cache) before any timing.

The thread policy is set here, whatever the caller's environment: BLAS on one thread (the
command line's policy: many small products), numba's pool with ``--threads`` threads (default
every core), of which the "1 thread" rows use one. The load average is printed beside the
table: on a shared machine, take the ratios, not the times. The last lines are the table of
the README (markdown).

Usage: python benchmarks/bench_backends.py [--trials 20000] [--series-d 100000] [--repeats 3] [--threads N]
"""

from __future__ import annotations

import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"


def _threads_asked(argv: list[str]) -> str:
    """``--threads N`` (or ``--threads=N``) of the command line, before numba is imported."""
    for i, arg in enumerate(argv):
        if arg.startswith("--threads="):
            return arg.split("=", 1)[1]
        if arg == "--threads" and i + 1 < len(argv):
            return argv[i + 1]
    return str(os.cpu_count() or 1)


os.environ["NUMBA_NUM_THREADS"] = _threads_asked(sys.argv)

import argparse
import contextlib
import time
from pathlib import Path

import numpy as np

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.kernels import NumbaBackend, resolve_backend
from robocal_uncertainty.montecarlo.engine import DEFAULT_BLOCK_SIZE, block_rng, run_trials
from robocal_uncertainty.montecarlo.streams import source_generator
from robocal_uncertainty.uncertainty import (
    EvaluationSettings,
    UncertaintySettings,
    evaluate_uncertainty,
    prepare_calibration_trials,
)
from robocal_uncertainty.uncertainty.calibration.trials import _SUB_BATCH as SUB_BATCH
from robocal_uncertainty.uncertainty.sources import stream_id

ROOT = Path(__file__).resolve().parents[1]
TEST_JOINTS = np.radians([-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451])
UR10_TEST_JOINTS = np.array([0.934319, -1.79251, 1.5196, 0.272862, 0.934269, -1.57075])


def _clock(threads: int) -> float:
    return time.process_time() if threads == 1 else time.perf_counter()


def _set_threads(threads: int) -> None:
    import numba

    numba.set_num_threads(threads)


def per_trial(trials, n: int, threads: int, repeats: int) -> float:
    """Seconds per trial of the trial blocks (best of `repeats`)."""
    best = np.inf
    for _ in range(repeats):
        start = _clock(threads)
        run_trials(trials, seed=0, n_trials=n)
        best = min(best, _clock(threads) - start)
    return best / n


def draws_per_trial(trials, n: int, repeats: int) -> float:
    """CPU seconds per trial of the sources' draws alone, drawn as the trial block draws them:
    per engine block of trials, a source drawn by one fill of its generator (``draws_by_rows``)
    sub-batch by sub-batch, the others the whole block at once."""
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        for b, lo in enumerate(range(0, n, DEFAULT_BLOCK_SIZE)):
            size = min(DEFAULT_BLOCK_SIZE, n - lo)
            rng = block_rng(0, b)
            for source in trials.sources:
                stream = source_generator(rng, stream_id(source.name))
                if getattr(source, "draws_by_rows", False):
                    for sub in range(0, size, SUB_BATCH):
                        source.draw(stream, min(SUB_BATCH, size - sub))
                else:
                    source.draw(stream, size)
        best = min(best, time.process_time() - start)
    return best / n


def walk_per_trial(trials, threads: int, n: int = 256, repeats: int = 20) -> float:
    """Seconds per trial of one kinematics pass of the re-identification."""
    rng = np.random.default_rng(0)
    predictor = trials.solver.predictor
    q = trials.joint_positions + rng.uniform(-1e-4, 1e-4, (n, *trials.joint_positions.shape))
    params = trials.problem.parameters(np.repeat(trials.x_hat[None], n, axis=0))
    predictor(params, q)
    best = np.inf
    for _ in range(repeats):
        start = _clock(threads)
        predictor(params, q)
        best = min(best, _clock(threads) - start)
    return best / n


def reid_per_trial(trials, threads: int, n: int = 256, repeats: int = 10) -> float:
    """Seconds per trial of the re-identification alone (``solver.solve`` of one sub-batch of
    the block's own perturbed inputs): what the backend's kernel replaces."""
    from robocal_uncertainty.uncertainty.sources import TrialBatch

    rng = np.random.default_rng(0)
    batch = TrialBatch(n_trials=n)
    for source in trials.sources:
        source.apply(source.draw(source_generator(rng, stream_id(source.name)), n), batch)
    measurement = trials.problem.measurement
    pts = measurement.perturb(trials.points[None], batch.points)
    q = trials.joint_positions[None] + batch.joints
    lambdas = np.full(n, trials.lambda_star)
    trials.solver.solve(q, pts, batch.weights, lambdas, trials.x_hat)
    best = np.inf
    for _ in range(repeats):
        start = _clock(threads)
        trials.solver.solve(q, pts, batch.weights, lambdas, trials.x_hat)
        best = min(best, _clock(threads) - start)
    return best / n


def _campaign(model, n_poses: int, six_dof: bool):
    settings = SimulationSettings(n_poses=n_poses, orientation_std=float(np.radians(0.01)) if six_dof else None)
    return simulate_campaign(model, settings, seed=1).campaign


def grid(
    args: argparse.Namespace, all_threads: int
) -> tuple[dict[tuple[int, str, int], float], dict[tuple[int, str], float]]:
    """Print the grid; return the seconds per trial by (poses, kind, threads; 0 for numpy), and
    those of the draws alone by (poses, kind)."""
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    configs = [("numpy", 1)]
    if NumbaBackend().available():
        configs += [("numba", 1)] + ([("numba", all_threads)] if all_threads > 1 else [])
    header = (
        f"{'case':<22}{'backend':<18}{'us/trial':>10}{'ratio':>8}{'w/o draws':>11}{'ratio':>8}"
        f"{'re-id us':>10}{'ratio':>8}{'walk us':>9}{'ratio':>8}"
    )
    print(header)
    print("-" * len(header))
    point_cost: dict[tuple[int, str, int], float] = {}
    reid_cost: dict[tuple[int, str, int], float] = {}
    draw_cost: dict[tuple[int, str], float] = {}
    for n_poses in (53, 632):
        for six_dof in (False, True):
            campaign = _campaign(model, n_poses, six_dof)
            calibration = identify(model, campaign)
            sources = ("tracker", "encoder", "tracker_orientation") if six_dof else ("tracker", "encoder")
            settings = UncertaintySettings(sources=sources)
            n = args.trials if n_poses == 53 else max(1000, args.trials // 10)
            draws = None
            base = None
            for backend, threads in configs:
                if backend == "numba":
                    _set_threads(threads)
                trials = prepare_calibration_trials(
                    model, campaign, TEST_JOINTS, settings=settings, calibration=calibration, backend=backend
                )
                run_trials(trials, seed=0, n_trials=min(n, 2000))  # warm-up
                if draws is None:
                    draws = draws_per_trial(trials, n, args.repeats)
                t = per_trial(trials, n, threads, args.repeats)
                walk = walk_per_trial(trials, threads)
                reid = reid_per_trial(trials, threads)
                rest = t - draws
                if base is None:
                    base = (t, rest, reid, walk)
                kind = "6-DOF" if six_dof else "point"
                key = (n_poses, kind, threads if backend == "numba" else 0)
                point_cost[key] = t
                reid_cost[key] = reid
                label = f"{backend}, {threads} thread{'s' if threads > 1 else ''}"
                print(
                    f"{n_poses:>3} poses, {kind:<12}{label:<18}{t * 1e6:>10.2f}{base[0] / t:>7.2f}x"
                    f"{rest * 1e6:>11.2f}{base[1] / rest:>7.2f}x{reid * 1e6:>10.2f}{base[2] / reid:>7.2f}x"
                    f"{walk * 1e6:>9.2f}{base[3] / walk:>7.2f}x"
                )
            draw_cost[(n_poses, "6-DOF" if six_dof else "point")] = draws
            print(
                f"{'':<22}random draws alone: {draws * 1e6:.2f} us/trial (the same for every backend); "
                f"a kernel that cost nothing would give {base[0] / draws:.1f}x numpy per trial"
            )
    print()
    for key in sorted({(k[2]) for k in point_cost}):
        name = "numpy" if key == 0 else f"numba, {key} thread{'s' if key > 1 else ''}"
        six = [point_cost[(p, "6-DOF", key)] / point_cost[(p, "point", key)] for p in (53, 632)]
        growth = point_cost[(632, "point", key)] / point_cost[(53, "point", key)]
        six_reid = [reid_cost[(p, "6-DOF", key)] / reid_cost[(p, "point", key)] for p in (53, 632)]
        growth_reid = reid_cost[(632, "point", key)] / reid_cost[(53, "point", key)]
        print(
            f"{name}: 6-DOF / point per trial {six[0]:.2f}x (53 poses), {six[1]:.2f}x (632 poses); "
            f"point trial 632 / 53 poses {growth:.1f}x for {632 / 53:.1f}x the poses"
        )
        print(
            f"{'':<{len(name) + 2}}re-identification alone: 6-DOF / point {six_reid[0]:.2f}x (53 poses), "
            f"{six_reid[1]:.2f}x (632 poses); 632 / 53 poses {growth_reid:.1f}x"
        )
    return point_cost, draw_cost


def markdown_table(
    cost: dict[tuple[int, str, int], float],
    draw_cost: dict[tuple[int, str], float],
    series: dict[int, tuple[float, float]],
) -> None:
    """The README's table: µs per trial and the ratio against numpy, same run."""
    threads = sorted({key[2] for key in cost} - {0})
    names = ["numpy"] + [f"numba, {t} thread{'s' if t > 1 else ''}" for t in threads]
    print("\n| case | " + " | ".join(names) + " |")
    print("| --- |" + " --- |" * len(names))
    for n_poses in (53, 632):
        for kind in ("point", "6-DOF"):
            base = cost[(n_poses, kind, 0)]
            cells = [f"{base * 1e6:.3g} µs"] + [
                f"{cost[(n_poses, kind, t)] * 1e6:.3g} µs, {base / cost[(n_poses, kind, t)]:.2f}x" for t in threads
            ]
            print(f"| {n_poses} poses, {kind} | " + " | ".join(cells) + " |")
    for n_poses in (53, 632):
        for kind in ("point", "6-DOF"):
            draws = draw_cost[(n_poses, kind)]
            ceiling = cost[(n_poses, kind, 0)] / draws
            print(
                f"| {n_poses} poses, {kind}: draws alone, any backend (ceiling) | {draws * 1e6:.3g} µs |"
                + f" {ceiling:.1f}x |" * len(threads)
            )
    six = [[cost[(p, "6-DOF", t)] / cost[(p, "point", t)] for t in [0, *threads]] for p in (53, 632)]
    print("| 6-DOF / point, 53 poses | " + " | ".join(f"{r:.2f}x" for r in six[0]) + " |")
    print("| 6-DOF / point, 632 poses | " + " | ".join(f"{r:.2f}x" for r in six[1]) + " |")
    if series:
        base_cpu, base_wall = series[0]
        cells = [f"{base_cpu:.1f} s CPU"] + [
            f"{series[t][0]:.1f} s CPU ({base_cpu / series[t][0]:.2f}x), {series[t][1]:.1f} s wall "
            f"({base_wall / series[t][1]:.2f}x)"
            for t in threads
            if t in series
        ]
        print("| UR10 series D, evaluate | " + " | ".join(cells) + " |")


def series_d(n: int, all_threads: int) -> dict[int, tuple[float, float]]:
    """Print and return the CPU and wall seconds of evaluate per thread count (0 for numpy)."""
    from robocal_uncertainty.importers.tracker_csv import read_tracker_csv

    model = load_robot_model(ROOT / "config/ur10.yaml")
    campaign = read_tracker_csv(ROOT / "test/data/ur10_laser_tracker/measurements_iso_cubes.csv")
    campaign = campaign.reorder_joints(model.joint_names)
    calibration = identify(model, campaign)
    print(f"\nUR10 series D, {campaign.n_poses} poses, default sources, {n} trials (evaluate_uncertainty, no budget)")
    configs = [("numpy", 1)]
    if NumbaBackend().available():
        configs += [("numba", 1)] + ([("numba", all_threads)] if all_threads > 1 else [])
    base = None
    times: dict[int, tuple[float, float]] = {}
    for backend, threads in configs:
        if backend == "numba":
            _set_threads(threads)
        ev = EvaluationSettings(
            uncertainty=UncertaintySettings(sources=("tracker", "encoder", "residual")),
            trials=n,
            backend=backend,
        )
        cpu, wall = time.process_time(), time.perf_counter()
        result = evaluate_uncertainty(model, campaign, UR10_TEST_JOINTS, ev, calibration=calibration)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        if base is None:
            base = (cpu, wall)
        times[threads if backend == "numba" else 0] = (cpu, wall)
        u = [a.standard_uncertainty * 1e6 for a in result.poses[0].axes]
        print(
            f"  {backend}, {threads} thread{'s' if threads > 1 else ''}: {cpu:.1f} s CPU ({base[0] / cpu:.2f}x), "
            f"{wall:.1f} s wall ({base[1] / wall:.2f}x); u = ({u[0]:.1f}, {u[1]:.1f}, {u[2]:.1f}) um"
        )
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20_000, help="trials at 53 poses (a tenth at 632)")
    parser.add_argument("--repeats", type=int, default=3, help="best of this many runs per timing")
    parser.add_argument("--series-d", type=int, default=0, metavar="N", help="also evaluate series D with N trials")
    parser.add_argument("--threads", type=int, help="numba's threads in the 'all threads' rows (default: every core)")
    args = parser.parse_args()
    all_threads = 1
    if NumbaBackend().available():
        import numba

        compile_s = NumbaBackend().warm_up()
        all_threads = int(numba.config.NUMBA_NUM_THREADS)
        print(f"numba kernel ready in {compile_s:.2f} s (compiled or loaded from the disk cache)")
    else:
        print("numba is not installed: numpy only (pip install '.[fast]')")
    for name in ("numpy", "numba"):
        with contextlib.suppress(ConfigError):  # not installed: nothing to describe
            print(f"backend {resolve_backend(name).describe()}")
    print(f"CPU cores: {os.cpu_count()}, numba threads: {all_threads}, BLAS threads: 1")
    print(f"load average at the start: {_load()}\n")
    cost, draw_cost = grid(args, all_threads)
    series = series_d(args.series_d, all_threads) if args.series_d else {}
    markdown_table(cost, draw_cost, series)
    print(f"\nload average at the end: {_load()}")
    return 0


def _load() -> str:
    """The 1, 5 and 15 minute load averages (what else ran on the machine)."""
    with contextlib.suppress(OSError):
        return ", ".join(f"{v:.1f}" for v in os.getloadavg())
    return "unknown"


if __name__ == "__main__":
    sys.exit(main())
