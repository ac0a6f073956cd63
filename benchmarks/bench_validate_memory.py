"""Peak memory and time of ``validate`` against the number of held-out poses.

The proof of a statement on a real 12 000-pose series must fit a normal machine. Set-up:
paper_arm, a simulated tracker-frame campaign of 53 training poses and a validation
campaign of the same robot and set-up (poses drawn by the same simulation), sources
tracker, encoder, residual, 5 000 trials (``validate``'s default), held out whole
(``validate --validation-campaign``). Each run is a fresh Python process, so its peak
resident set (``resource.getrusage``, process lifetime) is that run's alone.

- streamed (this code): held-out poses in chunks of
  :func:`~robocal_uncertainty.uncertainty.holdout.holdout_chunk_size` (640 at 5 000 trials);
- one chunk (the earlier behaviour: every held-out pose in one Monte Carlo), measured at
  sizes that fit, to give its memory per held-out pose.

Printed: held-out poses, wall and CPU time of ``validate_holdout`` (CPU: this process alone, what a
shared machine does not blur), peak RSS, and the memory per
held-out pose (the slope of peak RSS between two sizes) before and after. Nothing here is a
pass/fail test.

With ``--streamed-only``: the streamed run alone, once per backend of ``--backend`` (e.g.
``--backend numpy numba``), to time ``validate`` of ``--held-out`` poses per backend.

Usage: python benchmarks/bench_validate_memory.py [--held-out 12000] [--trials 5000]
       [--streamed-only --backend numpy numba]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _child(n_held: int, trials: int, one_chunk: bool, backend: str) -> None:
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
    from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
    from robocal_uncertainty.uncertainty import holdout
    from robocal_uncertainty.uncertainty.sources import UncertaintySettings

    if one_chunk:
        holdout.HOLDOUT_POSE_TRIALS = 10**15  # every held-out pose in one Monte Carlo
    model = load_robot_model(ROOT / "config" / "paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(n_poses=53 + n_held, frame="tracker"), seed=5).campaign
    train, held = sim.subset(np.arange(53)), sim.subset(np.arange(53, 53 + n_held))
    settings = UncertaintySettings(sources=("tracker", "encoder", "residual"))
    start, cpu = time.perf_counter(), time.process_time()
    result = holdout.validate_holdout(
        model, train, validation_campaign=held, settings=settings, trials=trials, backend=backend
    )
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    x = result.axes[0]
    print(
        json.dumps(
            {
                "n_held": n_held,
                "seconds": elapsed,
                "cpu_seconds": cpu,
                "peak_rss": peak,
                "inside_x": x.inside_fraction,
                "normalized_rms_x": x.normalized_rms,
                "frame_moved": bool(result.frame_comparison is not None and result.frame_comparison.moved),
            }
        )
    )


def _run(n_held: int, trials: int, one_chunk: bool, backend: str = "numpy") -> dict[str, float]:
    cmd = [sys.executable, __file__, "--child", str(n_held), "--trials", str(trials), "--backend", backend]
    if one_chunk:
        cmd.append("--one-chunk")
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--held-out", type=int, default=12_000)
    parser.add_argument("--trials", type=int, default=5_000)
    parser.add_argument("--child", type=int)
    parser.add_argument("--one-chunk", action="store_true")
    parser.add_argument("--backend", nargs="+", default=["numpy"], help="trial backends (default numpy)")
    parser.add_argument("--streamed-only", action="store_true", help="time the streamed run per backend only")
    args = parser.parse_args()
    if args.child is not None:
        _child(args.child, args.trials, args.one_chunk, args.backend[0])
        return
    if args.streamed_only:
        base = None
        for backend in args.backend:
            r = _run(args.held_out, args.trials, False, backend)
            base = base or r["seconds"]
            print(
                f"{backend:<6} {args.held_out:>6} held-out poses, {args.trials} trials: {r['seconds']:8.1f} s wall "
                f"({base / r['seconds']:.2f}x), {r['cpu_seconds']:.1f} s CPU, "
                f"peak RSS {r['peak_rss'] / 2**20:6.0f} MiB "
                f"(x inside {100 * r['inside_x']:.1f} %)",
                flush=True,
            )
        return
    mib = 2**20
    rows = []
    for label, n, one in (
        ("one chunk (before)", 160, True),
        ("one chunk (before)", 640, True),
        ("streamed (after)", 1280, False),
        ("streamed (after)", args.held_out, False),
    ):
        r = _run(n, args.trials, one)
        rows.append((label, r))
        print(
            f"{label:<20} {n:>6} held-out poses, {args.trials} trials: {r['seconds']:8.1f} s, "
            f"peak RSS {r['peak_rss'] / mib:8.0f} MiB (x inside {100 * r['inside_x']:.1f} %, "
            f"normalised RMS {r['normalized_rms_x']:.3f})",
            flush=True,
        )
    (_, b1), (_, b2), (_, a1), (_, a2) = rows
    before = (b2["peak_rss"] - b1["peak_rss"]) / (b2["n_held"] - b1["n_held"])
    after = (a2["peak_rss"] - a1["peak_rss"]) / (a2["n_held"] - a1["n_held"])
    print(f"memory per held-out pose: before {before / 1e6:.2f} MB, after {after / 1e6:.3f} MB")
    extrapolated = b1["peak_rss"] + before * (args.held_out - b1["n_held"])
    print(
        f"one chunk extrapolated to {args.held_out} poses: {extrapolated / 2**30:.1f} GiB; "
        f"streamed, measured: {a2['peak_rss'] / 2**30:.2f} GiB in {a2['seconds']:.0f} s"
    )


if __name__ == "__main__":
    main()
