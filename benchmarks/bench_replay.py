"""Replay of a raw recording against what rosbags needs to deserialize the same bag.

Writes one simulated raw recording (default: the seed's arm, 53 poses, 125 Hz joint states,
500 Hz tracker points, 2 s dwells, 3 s moves: about 170 000 messages) to a temporary MCAP file,
then, in this process, times on that same file:

- baseline: rosbags (``AnyReader``) reading the bag and deserializing every message on the
  joint and tracker topics, nothing else;
- replay: :func:`~robocal_uncertainty.pipeline.replay.replay_bag` without calibration, i.e.
  reading, decoding, static-pose detection and averaging into samples (what ``replay`` does
  before it calibrates).

Both are timed ``--repeat`` times alternately, in CPU seconds of this process (both run in one
thread; on a shared machine the wall clock mostly measures the wait for a core), and the best
of each is kept; the ratio replay / baseline is printed. Nothing here is a pass/fail test.

Usage: ``python benchmarks/bench_replay.py [--poses 53] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from rosbags.highlevel import AnyReader

from robocal_uncertainty.bagio.campaign_format import JOINT_TOPIC, POINT_TOPIC
from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, write_raw_bag
from robocal_uncertainty.bagio.ros_messages import ros_typestore
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.pipeline.replay import replay_bag

REPO = Path(__file__).resolve().parents[1]


def deserialize_only(path: Path) -> int:
    """Deserialize every joint and tracker message with rosbags; the number of messages."""
    count = 0
    with AnyReader([path], default_typestore=ros_typestore()) as reader:
        connections = [c for c in reader.connections if c.topic in (JOINT_TOPIC, POINT_TOPIC)]
        for connection, _, raw in reader.messages(connections=connections):
            reader.deserialize(raw, connection.msgtype)
            count += 1
    return count


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=53)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    model = load_robot_model(REPO / "config" / "paper_arm.yaml")
    simulated = simulate_campaign(model, SimulationSettings(n_poses=args.poses), seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "raw.mcap"
        write_raw_bag(path, simulated, RawBagSettings(), seed=3)
        base, ours = float("inf"), float("inf")
        messages = samples = 0
        for _ in range(args.repeat):
            start = time.process_time()
            messages = deserialize_only(path)
            base = min(base, time.process_time() - start)
            start = time.process_time()
            result = replay_bag(path, model, calibrate=False)
            ours = min(ours, time.process_time() - start)
            samples = len(result.samples)
        size = path.stat().st_size / 2**20
    print(f"raw bag: {args.poses} poses, {messages} messages, {size:.1f} MiB (125 Hz joints, 500 Hz tracker)")
    print(f"rosbags deserialize only: {base:6.2f} s CPU  ({messages / base:,.0f} messages/s)")
    print(f"replay (read + collect):  {ours:6.2f} s CPU  ({messages / ours:,.0f} messages/s), {samples} samples")
    print(f"replay / deserialize: {ours / base:.2f}x (best of {args.repeat} each, alternated)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
