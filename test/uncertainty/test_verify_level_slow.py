"""The level test of ``verify`` (a check's error level against the calibration's validated level).

Simulated UR10 sessions (known truth: nothing changed but the tracker, or a joint-2 offset
drift) and the shipped real UR10 series (held-out poses of the calibration's own series):
false alarms near the 5 % level at every check size, power that does not fall as a check grows.
Measured with these tests (seeds as written, OPENBLAS_NUM_THREADS=1, loaded two-core machine;
printed by ``python -m pytest -q -m slow test/uncertainty/test_verify_level_slow.py -s``, 9 min):
- simulated, rejected at 0 / 0.005 / 0.01 deg of joint-2 drift: 4.4 / 65.6 / 98.9 % (10 poses),
  7.8 / 75.6 / 100 % (20), 8.9 / 95.6 / 100 % (50), 90 checks each;
- real series D, same session: 90.0 / 87.5 / 92.5 / 87.5 % consistent at 10 / 20 / 50 / 200
  poses (8 calibrations x 5 checks), below the nominal 95 %: one calibration of the eight
  predicts its other poses 1.62x worse in mean square than its four 5-fold splits say, and
  fails most of its checks (the others fail 0-2 of 20). The repeated splits and the measured
  dispersion fixed the reference's noise, not a calibration whose own held-out level departs
  from that of calibrations on 42 of its poses.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.core import EncoderNoise, TrackerNoise, identify, load_robot_model
from robocal_uncertainty.core.simulation import (
    SessionSimulationSettings,
    draw_session_change,
    simulate_session,
    simulate_sessions,
)
from robocal_uncertainty.importers import read_tracker_csv
from robocal_uncertainty.uncertainty.sessions.state import session_state
from robocal_uncertainty.uncertainty.sessions.validated_level import validated_level
from robocal_uncertainty.uncertainty.sessions.verification import verify_session

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
STILL = SessionSimulationSettings(
    n_sessions=1, n_poses=53, tool_remount_std=0.0, joint_offset_std=0.0, temperature_std=0.0
)


def _state(model, campaign, tracker, encoder):
    cal = identify(model, campaign)
    state, _ = session_state(cal, campaign, tracker, encoder)
    level = validated_level(model, campaign, tracker, encoder, reference=state, retool=False)
    return cal, dataclasses.replace(state, validated_level=level)


def test_simulated_sessions_false_alarms_and_power_by_check_size() -> None:
    model = dataclasses.replace(load_robot_model(ROOT / "robocal_uncertainty" / "data" / "ur10.yaml"), base_known=False)
    sizes = (10, 20, 50)
    drifts = (0.0, 0.005, 0.01)
    rejected = {(n, d): 0 for n in sizes for d in drifts}
    count = 0
    for seed in range(30):
        sim = simulate_sessions(model, STILL, seed=seed)
        first = sim.sessions[0]
        cal, state = _state(model, first.campaign, first.settings.tracker_noise, first.settings.encoder_noise)
        rng = np.random.default_rng(2000 + seed)
        for k in range(3):
            change = draw_session_change(model, STILL, rng=rng, reference=True)
            for d in drifts:
                drifted = dataclasses.replace(
                    change, joint_offset_drift=(0.0, float(np.radians(d)), 0.0, 0.0, 0.0, 0.0)
                )
                for n in sizes:
                    settings = dataclasses.replace(first.settings, n_poses=n)
                    check = simulate_session(model, sim.robot_parameters, drifted, settings, rng=rng)
                    result = verify_session(cal.model, state, check.campaign, null_trials=200, seed=k)
                    assert result.test == "error level"
                    rejected[(n, d)] += not result.consistent
            count += 1
    rates = {key: value / count for key, value in rejected.items()}
    for n in sizes:
        print(f"simulated, {n} poses: rejected " + ", ".join(f"{rates[(n, d)]:.3f} at {d} deg" for d in drifts))
    for n in sizes:
        assert rates[(n, 0.0)] <= 0.1  # nominal 5 %: binomial sd 2.2 % over 90 checks
    for d in drifts[1:]:
        assert rates[(10, d)] <= rates[(20, d)] + 0.05 <= rates[(50, d)] + 0.1  # power does not fall with size
    assert rates[(50, 0.01)] >= 0.8


def test_real_series_same_session_checks_by_size() -> None:
    """Held-out poses of the calibration's own (real) series: consistent near 95 % at every size."""
    model = load_robot_model(ROOT / "robocal_uncertainty" / "data" / "ur10.yaml")
    campaign = read_tracker_csv(ROOT / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv")
    sizes = (10, 20, 50, 200)
    consistent = {n: [] for n in sizes}
    for c in range(8):
        order = np.random.default_rng([31, c]).permutation(campaign.n_poses)
        train = campaign.subset(np.sort(order[:53]))
        cal = identify(model, train)
        state, _ = session_state(cal, train, TrackerNoise(), EncoderNoise())
        level = validated_level(model, train, TrackerNoise(), EncoderNoise(), reference=state)
        state = dataclasses.replace(state, validated_level=level)
        for n in sizes:
            for k in range(5):
                pick = np.random.default_rng([31, c, n, k]).choice(order[53:], n, replace=False)
                result = verify_session(cal.model, state, campaign.subset(np.sort(pick)), retool=True, null_trials=200)
                consistent[n].append(result.consistent)
    rates = {n: float(np.mean(v)) for n, v in consistent.items()}
    print("UR10 series D, same session, consistent: " + ", ".join(f"{rates[n]:.3f} at {n} poses" for n in sizes))
    for n in sizes:
        assert rates[n] >= 0.85  # nominal 95 %; 40 checks over 8 calibrations, clustered by calibration
