"""Paths and settings shared by the pipeline tests (a uniquely named helper module)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal_uncertainty.pipeline import CollectorSettings

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "test" / "data"
BASE_BAG = DATA / "paper_arm_base_raw.mcap"
TRACKER_BAG = DATA / "paper_arm_tracker_raw.mcap"
# The test bags dwell only 0.3 s per pose (to stay small): a short window and guard.
COLLECTOR = CollectorSettings(window_s=0.1, guard_s=0.025, min_points=10)
# Seed test configuration (section 3.2) and a second one, in rad.
TEST_JOINTS = np.radians(
    [[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451], [30.0, -180.0, 45.0, 10.0, -20.0, 5.0]]
)
TRIALS = 400
SEED = 7
