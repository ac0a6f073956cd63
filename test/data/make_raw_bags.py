"""Write the small raw test bags of ``test/pipeline`` (deterministic; run from anywhere).

* ``paper_arm_base_raw.mcap``: paper arm, 30 poses, points in the robot base frame
  (``base_link``), 125 Hz joint states, 250 Hz tracker points, 0.3 s dwells, 0.15 s moves,
  starting and ending at home.
* ``paper_arm_tracker_raw.mcap``: paper arm with an unknown tracker pose, 18 poses in the
  ``laser_tracker`` frame, 100 Hz / 200 Hz, ending during the last dwell.

Dwells and moves are far shorter than on a real robot to keep the files small (a few
hundred kB); the static detection in the tests is tuned to match (0.12 s window). The
ground truth (static windows, true joints, true points) is stored in each file's
``robocal_raw_truth`` metadata record.

Usage: ``python test/data/make_raw_bags.py``
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, write_raw_bag
from robocal_uncertainty.core import SimulationSettings, load_robot_model, simulate_campaign

HERE = Path(__file__).resolve().parent
PAPER_ARM = HERE.parents[1] / "robocal_uncertainty" / "data" / "paper_arm.yaml"
BASE_BAG = HERE / "paper_arm_base_raw.mcap"
TRACKER_BAG = HERE / "paper_arm_tracker_raw.mcap"


def main() -> None:
    """Write both bags, replacing existing ones."""
    model = load_robot_model(PAPER_ARM)
    base = simulate_campaign(model, SimulationSettings(n_poses=30, frame="base"), seed=1)
    settings = RawBagSettings(
        joint_rate_hz=125.0, tracker_rate_hz=250.0, dwell_s=0.3, move_s=0.15, dropout_rate_hz=0.5, dropout_s=(0.02, 0.1)
    )
    write_raw_bag(BASE_BAG, base, settings, seed=11, overwrite=True)

    unknown_base = dataclasses.replace(model, base_known=False)
    tracker = simulate_campaign(unknown_base, SimulationSettings(n_poses=18, frame="tracker"), seed=2)
    settings = RawBagSettings(
        joint_rate_hz=100.0,
        tracker_rate_hz=200.0,
        dwell_s=0.3,
        move_s=0.15,
        profile="cosine",
        return_home=False,
        dropout_rate_hz=0.5,
        dropout_s=(0.02, 0.1),
    )
    write_raw_bag(TRACKER_BAG, tracker, settings, seed=12, overwrite=True)
    for path in (BASE_BAG, TRACKER_BAG):
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    main()
