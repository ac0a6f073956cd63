"""Shared, session-scoped fixtures: one simulated campaign and one small Monte Carlo run."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import (
    Campaign,
    RobotModel,
    SimulationSettings,
    load_robot_model,
    simulate_campaign,
)
from robocal_uncertainty.uncertainty import (
    CalibrationUncertainty,
    UncertaintySettings,
    evaluate_uncertainty,
)

# Seed test configuration (section 3.2), in degrees.
PAPER_TEST_JOINTS_DEG = (-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451)
TRIALS = 1000
REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Setup:
    model: RobotModel
    campaign: Campaign
    test_joints: np.ndarray
    result: CalibrationUncertainty


@pytest.fixture(scope="session")
def setup() -> Setup:
    model = load_robot_model(REPO / "config" / "paper_arm.yaml")
    sim = simulate_campaign(model, SimulationSettings(), seed=1)
    qt = np.radians(PAPER_TEST_JOINTS_DEG)
    result = evaluate_uncertainty(
        model,
        sim.campaign,
        qt,
        uncertainty=UncertaintySettings(sources=("tracker", "encoder")),
        trials=TRIALS,
        seed=1,
    )
    return Setup(model, sim.campaign, qt, result)
