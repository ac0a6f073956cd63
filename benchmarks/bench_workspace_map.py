"""Time and peak memory of a workspace uncertainty map on one process, two local processes
and a two-worker Dask LocalCluster.

The map: the seed's arm, a simulated 53-pose campaign, tracker and encoder noise, 2 000
configurations drawn uniformly inside the joint limits, 10^4 trials (blocks of 1 000).
Each executor runs in a fresh Python process (so peak RSS is that run's), measured there:
- time: wall clock of ``map_workspace`` alone; the cluster start is timed apart;
- driver: peak resident set (``resource.getrusage``, process lifetime, includes the
  set-up) and peak traced Python/numpy allocation during the map (``tracemalloc``);
- workers: the largest resident set of any child process and the largest sum over the
  children, sampled every 50 ms with psutil (not measured without psutil).
Ratios are against the one-process baseline measured in the same invocation. The three
maps are also checked to be bit-identical. Nothing here is a pass/fail test.

Usage: python benchmarks/bench_workspace_map.py [--configurations 2000] [--trials 10000]
"""

from __future__ import annotations

import os

# One BLAS thread per process, as the command line does (see robocal_uncertainty/cli/__init__.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import hashlib
import importlib
import json
import resource
import subprocess
import sys
import threading
import time
import tracemalloc

import numpy as np

MODES = ("one process", "two local processes", "Dask LocalCluster, 2 workers")


def _peak_rss_mib() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return usage / 1024.0 if sys.platform != "darwin" else usage / 2**20


class _ChildSampler:
    """Largest RSS of any descendant process, and of their sum, sampled in a thread."""

    def __init__(self, period_s: float = 0.05) -> None:
        try:
            import psutil
        except ImportError:
            self.psutil = None
            return
        self.psutil = psutil
        self.me = psutil.Process()
        self.period_s = period_s
        self.max_single = self.max_total = 0.0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self.stop.is_set():
            total = 0.0
            for child in self.me.children(recursive=True):
                try:
                    rss = child.memory_info().rss / 2**20
                except self.psutil.Error:
                    continue
                total += rss
                self.max_single = max(self.max_single, rss)
            self.max_total = max(self.max_total, total)
            self.stop.wait(self.period_s)

    def __enter__(self) -> _ChildSampler:
        if self.psutil is not None:
            self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.psutil is not None:
            self.stop.set()
            self.thread.join()


def run_mode(mode: int, n_configurations: int, trials: int) -> dict[str, object]:
    """One map with executor `mode` in this process; returns the measurements."""
    from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
    from robocal_uncertainty.montecarlo.executor import open_executor
    from robocal_uncertainty.uncertainty.sources import UncertaintySettings
    from robocal_uncertainty.uncertainty.workspace_map import map_workspace, sample_configurations

    model = load_robot_model("config/paper_arm.yaml")
    campaign = simulate_campaign(model, SimulationSettings(), seed=1).campaign.reorder_joints(model.joint_names)
    calibration = identify(model, campaign)
    settings = UncertaintySettings(sources=("tracker", "encoder"))
    q = sample_configurations(model, n_configurations, rng=np.random.default_rng(0))
    start = time.perf_counter()
    with (
        _ChildSampler() as children,
        open_executor(workers=1 if mode == 0 else 2, dask="local" if mode == 2 else None) as executor,
    ):
        if mode == 2:
            # Spawned Dask workers import the package on their first task: count it as start-up.
            executor.client.run(importlib.import_module, "robocal_uncertainty.uncertainty.workspace_map")
        started = time.perf_counter() - start
        tracemalloc.start()
        t0 = time.perf_counter()
        wmap = map_workspace(
            model, campaign, q, settings=settings, calibration=calibration, trials=trials, seed=0, executor=executor
        )
        elapsed = time.perf_counter() - t0
        _, traced_peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    digest = hashlib.sha256(np.ascontiguousarray(wmap.covariance).tobytes() + wmap.mean.tobytes()).hexdigest()
    return {
        "seconds": elapsed,
        "start_seconds": started,
        "driver_peak_rss_mib": _peak_rss_mib(),
        "driver_traced_peak_mib": traced_peak / 2**20,
        "worker_max_rss_mib": children.max_single if children.psutil is not None and mode else None,
        "workers_total_rss_mib": children.max_total if children.psutil is not None and mode else None,
        "digest": digest,
        "median_u_um": float(np.median(wmap.position_uncertainty)) * 1e6,
    }


def _fmt(value: object, base: object, unit: str) -> str:
    if not isinstance(value, float):
        return "-".rjust(22)
    ratio = f"({value / base:5.2f}x)" if isinstance(base, float) and base > 0 else " " * 8
    return f"{value:9.1f} {unit:<3} {ratio}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configurations", type=int, default=2000)
    parser.add_argument("--trials", type=int, default=10_000)
    parser.add_argument("--mode", type=int, choices=range(len(MODES)), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.mode is not None:
        print(json.dumps(run_mode(args.mode, args.configurations, args.trials)))
        return 0

    results = []
    for mode in range(len(MODES)):
        command = [sys.executable, __file__, "--mode", str(mode)]
        command += ["--configurations", str(args.configurations), "--trials", str(args.trials)]
        done = subprocess.run(command, check=True, capture_output=True, text=True)
        results.append(json.loads(done.stdout.strip().splitlines()[-1]))
    n_cols = 3 * args.configurations
    print(
        f"map: {args.configurations} configurations x {args.trials} trials, paper arm, tracker + encoder; "
        f"all samples would be {args.trials * n_cols * 8 / 2**20:.0f} MiB on the driver"
    )
    print(f"identical results on all executors: {'yes' if len({r['digest'] for r in results}) == 1 else 'NO'}")
    print(f"median u_pos {results[0]['median_u_um']:.1f} um; ratios against one process in ():")
    header = f"{'':30s} {'map time':>22s} {'driver peak RSS':>22s} {'driver traced peak':>22s}"
    header += f" {'largest worker RSS':>22s} {'all workers RSS':>22s}"
    print(header)
    base = results[0]
    for name, r in zip(MODES, results):
        row = f"{name:30s} {_fmt(r['seconds'], base['seconds'], 's')} "
        row += f"{_fmt(r['driver_peak_rss_mib'], base['driver_peak_rss_mib'], 'MiB')} "
        row += f"{_fmt(r['driver_traced_peak_mib'], base['driver_traced_peak_mib'], 'MiB')} "
        row += f"{_fmt(r['worker_max_rss_mib'], None, 'MiB')} {_fmt(r['workers_total_rss_mib'], None, 'MiB')}"
        print(row)
    print(f"Dask LocalCluster start and worker imports (not in the map time): {results[2]['start_seconds']:.1f} s")
    print("worker RSS: psutil samples of the child processes every 50 ms ('-': no workers, or psutil missing)")
    print("driver peak RSS is the process lifetime peak (includes imports, campaign and calibration)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
