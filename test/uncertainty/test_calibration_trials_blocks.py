"""The test configurations of a trial block are evaluated after the re-identification, in
slices of the whole block: the values do not depend on the slicing, bit for bit (slices of
256 trials are the sub-batches the re-identification runs in)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import SimulationSettings, identify, load_robot_model, simulate_campaign
from robocal_uncertainty.uncertainty import UncertaintySettings, evaluate_uncertainty
from robocal_uncertainty.uncertainty.calibration import trials as calibration_trials

ROOT = Path(__file__).resolve().parents[2]
TEST_JOINTS = np.radians([[-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451]])
DEFAULT_ELEMENTS = calibration_trials._TEST_ELEMENTS


@pytest.mark.parametrize(
    ("frame", "orientation_std", "sources", "n_test"),
    [
        ("tracker", None, ("tracker", "encoder"), 1),
        ("base", None, ("tracker", "encoder", "residual", "lambda", "pose_choice"), 100),
        ("tracker", 1e-4, ("tracker", "encoder", "residual", "tracker_orientation"), 3),
    ],
)
def test_block_values_do_not_depend_on_the_slices_of_test_configurations(
    frame: str, orientation_std: float | None, sources: tuple[str, ...], n_test: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = load_robot_model(ROOT / "config/paper_arm.yaml")
    campaign = simulate_campaign(
        model, SimulationSettings(n_poses=30, frame=frame, orientation_std=orientation_std), seed=3
    ).campaign
    calibration = identify(model, campaign)
    rng = np.random.default_rng(0)
    test_joints = np.vstack((TEST_JOINTS, rng.uniform(-2.0, 2.0, (n_test - 1, model.n_joints))))
    settings = UncertaintySettings(sources=sources)
    n = 700  # not a multiple of the 256-trial sub-batch

    def block(elements: int) -> tuple[np.ndarray, np.ndarray]:
        monkeypatch.setattr(calibration_trials, "_TEST_ELEMENTS", elements)
        result = evaluate_uncertainty(
            model, campaign, test_joints, uncertainty=settings, calibration=calibration, trials=n, seed=4, block_size=n
        )
        assert result.rotation_samples is not None
        return np.asarray(result.samples), np.asarray(result.rotation_samples)

    whole = block(10**9)  # one slice: the whole block
    for elements in (1, DEFAULT_ELEMENTS):  # slices of 256 trials; the default
        for got, expected in zip(block(elements), whole, strict=True):
            np.testing.assert_array_equal(got, expected)
