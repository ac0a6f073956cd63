"""Static-pose collector throughput and memory: 1 kHz joint states + 1 kHz tracker points.

Feeds a simulated campaign (6 joints; 2 s dwells, 3 s moves, encoder and tracker noise) for
`--minutes` of message time, as the live node would, and prints messages per second (CPU of
this process), the traced peak memory of the collector's allocations and the peak resident
memory of the process. Compare messages per second with the 2 000/s the live rate needs; the
peaks must not grow with the duration (run 1 and 10 minutes).

Usage: ``python benchmarks/bench_collector.py --minutes 10``
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import tracemalloc

import numpy as np

from robocal_uncertainty.pipeline import StaticPoseCollector

NAMES = tuple(f"joint{i + 1}" for i in range(6))


def run(minutes: float, rate_hz: float, *, trace: bool) -> tuple[int, int, float, int]:
    """Feed the stream once: (messages, samples, CPU seconds, traced peak bytes or 0)."""
    rng = np.random.default_rng(0)
    period = round(1e9 / rate_hz)
    n = round(minutes * 60 * rate_hz)
    collector = StaticPoseCollector(NAMES, tracker_frame_id="tracker")
    cycle = round(5.0 * rate_hz)  # 2 s dwell + 3 s move
    target = rng.uniform(-1, 1, 6)
    q = start = target.copy()
    samples = 0
    if trace:
        tracemalloc.start()
    started = time.process_time()
    t = 1_700_000_000_000_000_000
    for k in range(n):
        phase = k % cycle
        if phase == 0:
            start, target = q.copy(), rng.uniform(-1, 1, 6)
        if phase >= 2 * rate_hz:
            s = (phase - 2 * rate_hz) / (3 * rate_hz)
            q = start + (target - start) * (10 * s**3 - 15 * s**4 + 6 * s**5)
        t += period
        joints = q + rng.uniform(-1.5e-5, 1.5e-5, 6)
        point = q[:3] * 0.5 + rng.uniform(-5e-6, 5e-6, 3)
        samples += collector.add_joint_state(t, NAMES, joints) is not None
        samples += collector.add_tracker_point(t + period // 2, "tracker", point) is not None
    elapsed = time.process_time() - started
    peak = 0
    if trace:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return 2 * n, samples, elapsed, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=1.0)
    parser.add_argument("--rate-hz", type=float, default=1000.0)
    args = parser.parse_args()
    messages, samples, elapsed, _ = run(args.minutes, args.rate_hz, trace=False)
    _, _, _, peak = run(args.minutes, args.rate_hz, trace=True)
    print(
        f"{messages} messages ({args.minutes:g} min at {args.rate_hz:g} Hz + {args.rate_hz:g} Hz) in {elapsed:.1f} s "
        f"CPU, stream simulation included: {messages / elapsed:,.0f} messages/s (live needs "
        f"{2 * args.rate_hz:,.0f}/s); {samples} samples; traced peak {peak / 1e6:.2f} MB (second pass under "
        "tracemalloc)"
    )
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"peak resident memory of the process: {rss / 1024.0 if sys.platform != 'darwin' else rss / 2**20:.0f} MiB")


if __name__ == "__main__":
    main()
