"""The faster replay (own MCAP record walk, list-backed collector series, no cyclic GC during
a replay) gives the samples of the code before it, bit for bit.

* The messages :func:`read_mcap_file` reads are those of mcap's own ``StreamReader`` (an
  independent reader): same channels, log times and payload bytes, in the same order.
* The samples of the shipped raw bags and of a larger simulated recording (default rates:
  125 Hz joints, 500 Hz tracker, 2 s dwells) hash to the digests recorded with the code before
  the speed work (commit 4e0418c). A deliberate change of the static-pose semantics changes
  them: re-record with ``python test/pipeline/test_replay_same_samples.py`` on the commit
  before the change, and say so in its message.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import pytest
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

from robocal_uncertainty.bagio.mcap_stream import read_mcap_file
from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, write_raw_bag
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign
from robocal_uncertainty.pipeline import CollectorSettings, replay_bag

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "test" / "data"
MODEL = REPO / "robocal_uncertainty" / "data" / "paper_arm.yaml"
SHIPPED = ("paper_arm_base_raw.mcap", "paper_arm_tracker_raw.mcap")
SMALL = CollectorSettings(window_s=0.12, guard_s=0.03, average_s=0.2)
# sha256 of every sample's bytes, the dropped counts and the rejected dwells (see _digest),
# recorded with commit 4e0418c.
BEFORE = {
    ("paper_arm_base_raw.mcap", False): "b74f56dfafcf53bc01e6f012f43d0a0ecb9068b0626839b1907ea0fbbe43156b",
    ("paper_arm_base_raw.mcap", True): "b8a823ffcaaff9b30d5245310469d851837511adf140743aa8b56d63b2fdef96",
    ("paper_arm_tracker_raw.mcap", False): "e8db03d8217df724b866c927d424a7099bb4c327b9bab2546236cd5ec237e5d9",
    ("paper_arm_tracker_raw.mcap", True): "4ef4b80eef0973183cc1efdcb537a85f5e5fa9ad18e9839cc51e9f03498f0bc9",
    ("simulated", False): "98f32e901e5b75ede3aaddedbdefb2a05f9a79f8f352cca0fa74fb27c234ab6b",
}


def _digest(path: Path, settings: CollectorSettings | None, auto_window: bool) -> str:
    model = load_robot_model(MODEL)
    result = replay_bag(path, model, calibrate=False, collector=settings, auto_window=auto_window)
    h = hashlib.sha256()
    for s in result.samples:
        h.update(repr((s.stamp_ns, s.joint_state_count, s.tracker_point_count)).encode())
        for array in (s.joint_positions, s.joint_position_std, s.point, s.point_covariance):
            h.update(array.tobytes())
    h.update(repr((sorted(result.dropped.items()), result.rejected_dwells, len(result.samples))).encode())
    return h.hexdigest()


def _simulated(directory: Path) -> Path:
    """A 6-pose recording at the default rates and dwells (about 19 000 messages)."""
    path = directory / "simulated_raw.mcap"
    model = load_robot_model(MODEL)
    write_raw_bag(path, simulate_campaign(model, SimulationSettings(n_poses=6), seed=5), RawBagSettings(), seed=9)
    return path


def _mcap_reference(path: Path) -> list[tuple[str, str, int, bytes]]:
    """(topic, schema, log time, payload) of every message, by mcap's StreamReader."""
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    out = []
    with path.open("rb") as stream:
        for record in StreamReader(stream, validate_crcs=True).records:
            if isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
            elif isinstance(record, Message):
                out.append((*channels[record.channel_id], record.log_time, bytes(record.data)))
    return out


@pytest.mark.parametrize("name", SHIPPED)
def test_messages_are_those_mcap_reads(name: str) -> None:
    path = DATA / name
    got = read_mcap_file(path)
    assert not got.truncated
    mine = [(m.channel.topic, m.channel.schema_name, m.log_time_ns, m.data) for m in got.messages]
    reference = _mcap_reference(path)
    assert len(mine) == len(reference) > 1000
    assert mine == reference


@pytest.mark.parametrize("auto_window", [False, True], ids=["fixed", "auto_window"])
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_raw_bags_give_the_samples_of_before(name: str, auto_window: bool) -> None:
    assert _digest(DATA / name, SMALL, auto_window) == BEFORE[(name, auto_window)]


def test_simulated_recording_gives_the_samples_of_before(tmp_path: Path) -> None:
    assert _digest(_simulated(tmp_path), None, False) == BEFORE[("simulated", False)]


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        digests = {(n, a): _digest(DATA / n, SMALL, a) for n in SHIPPED for a in (False, True)}
        digests[("simulated", False)] = _digest(_simulated(Path(tmp)), None, False)
    for key, value in digests.items():
        print(f"    {key!r}: {value!r},")
    sys.exit(0)
