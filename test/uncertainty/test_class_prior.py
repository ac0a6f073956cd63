"""The class prior: the between-session component of one session, stated for the robot class.

References: the shipped file's own stated values, the conjugate pooling formula worked by hand,
and the moments rule of the between-session estimate on effects whose moments are negative.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.app.verification import calibrate_session
from robocal_uncertainty.core import EncoderNoise, TrackerNoise, load_robot_model
from robocal_uncertainty.core.calibration_file import read_calibration, read_session_state, write_calibration
from robocal_uncertainty.core.simulation import SessionSimulationSettings, simulate_sessions
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.sessions.between import BetweenSessions, _group_components
from robocal_uncertainty.uncertainty.sessions.class_prior import (
    load_class_prior,
    pooled_with_prior,
    prior_between_sessions,
)

DATA = Path(__file__).resolve().parents[2] / "robocal_uncertainty" / "data"


def test_the_shipped_ur10_prior_states_its_values_units_and_source() -> None:
    prior = load_class_prior("ur10")
    text = (DATA / "ur10_between_sessions.yaml").read_text()
    assert "Units:" in text and "rad" in text
    assert prior.joint_offsets_std == 6.0e-4 and prior.length_scale_std == 3.4e-4 and prior.dof == 3.0
    assert "issue 30" in prior.source and "0.1-0.6 mrad" in prior.source and "0.1-0.3 mm" in prior.source
    assert prior.path.startswith("shipped ur10")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("joint_offsets_std_rad: 1e-4\nlength_scale_std: 1e-4\ndof: 2\n", "no source"),
        ("joint_offsets_std_rad: 0\nlength_scale_std: 1e-4\ndof: 2\nsource: x\n", "must be positive"),
        ("length_scale_std: 1e-4\ndof: 2\nsource: x\n", "joint_offsets_std_rad missing"),
    ],
)
def test_a_prior_without_a_source_or_a_positive_spread_is_refused(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "prior.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_class_prior(path)
    with pytest.raises(ConfigError, match="neither a shipped prior"):
        load_class_prior(tmp_path / "missing.yaml")


def _between(tau_offsets: float, tau_scale: float, dof: float) -> BetweenSessions:
    names = ("joint2.theta", "joint3.theta", "length_scale")
    return BetweenSessions(
        names=names,
        covariance=np.diag([2 * tau_offsets**2, 2 * tau_offsets**2, 2 * tau_scale**2]),
        group_std={"joint_offsets": tau_offsets, "length_scale": tau_scale},
        group_dof={"joint_offsets": 2 * dof, "length_scale": dof},
        dof=dof,
        n_sessions=2,
        session_effects=np.zeros((1, 3)),
        session_effects_std=np.zeros((1, 3)),
    )


def test_pooling_with_the_prior_by_hand() -> None:
    prior = load_class_prior("ur10")
    pooled = pooled_with_prior(_between(1e-3, 0.0, 1.0), prior)
    # offsets: (3 * 0.6^2 + 2 * 1.0^2) / 5 mrad^2; length scale: a zero estimate on 1 dof pooled
    # with 3 dof of 340 ppm gives 3/4 of the prior's variance, never zero.
    assert pooled.group_std["joint_offsets"] == pytest.approx(np.sqrt((3 * 0.36e-6 + 2 * 1e-6) / 5))
    assert pooled.group_std["length_scale"] == pytest.approx(np.sqrt(0.75) * 3.4e-4)
    assert pooled.group_dof == {"joint_offsets": 5.0, "length_scale": 4.0} and pooled.dof == 4.0
    assert np.diag(pooled.covariance) == pytest.approx([2 * (3 * 0.36e-6 + 2 * 1e-6) / 5] * 2 + [2 * 0.75 * 3.4e-4**2])
    assert pooled.to_dict()["class_prior"]["source"] == prior.source


def test_disagreeing_sessions_whose_effect_moments_are_negative_are_not_zero() -> None:
    """The moments rule: effects smaller than their stated covariance give a zero component unless
    the sessions disagree (an F test of the level), then the effects' raw mean square."""
    e = np.array([[2e-5, -1e-5, 3e-5]])
    v = np.full((1, 3), 1e-8)  # stated variance larger than every e^2: moments negative
    names = ("joint2.theta", "joint3.theta", "length_scale")
    diag, std, dof = _group_components(names, e, v, disagree=False)
    assert np.all(diag == 0.0) and std == {"joint_offsets": 0.0, "length_scale": 0.0}
    diag, std, dof = _group_components(names, e, v, disagree=True)
    assert diag == pytest.approx([(4e-10 + 1e-10) / 2] * 2 + [9e-10])
    assert std["joint_offsets"] == pytest.approx(np.sqrt(2.5e-10 / 2)) and dof == {
        "joint_offsets": 2.0,
        "length_scale": 1.0,
    }


def test_one_session_with_the_class_prior_states_a_future_session(tmp_path: Path) -> None:
    model = dataclasses.replace(load_robot_model(DATA / "ur10.yaml"), base_known=False)
    first = simulate_sessions(model, SessionSimulationSettings(n_sessions=1, n_poses=40), seed=2).sessions[0]
    prior = load_class_prior("ur10")
    noise = {"tracker_noise": TrackerNoise(), "encoder_noise": EncoderNoise()}
    alone = calibrate_session(model, first.campaign, validate_level=False, **noise)
    assert alone.state is not None and alone.state.scope == "session"
    assert alone.state.between_session_covariance is None  # no prior named: nothing assumed
    cal = calibrate_session(model, first.campaign, validate_level=False, class_prior=prior, **noise)
    state = cal.state
    assert state is not None and state.scope == "future sessions"
    names = state.between_session_names
    assert "length_scale" in names and "joint2.theta" in names
    expected = [2 * (3.4e-4 if n == "length_scale" else 6e-4) ** 2 for n in names]
    assert np.diag(state.between_session_covariance) == pytest.approx(expected)
    assert state.between_session_dof == 3.0
    path = tmp_path / "cal.json"
    write_calibration(path, cal.result, robot=model.name, session=state)
    again = read_session_state(read_calibration(path))
    assert again is not None and again.scope == "future sessions"
    assert again.extra["between_session"]["class_prior"]["robot_class"] == prior.robot_class
    assert "class prior alone" in again.extra["between_session"]["model"]
    direct = prior_between_sessions(cal.result.model, first.campaign, prior)
    assert direct.names == names


def test_calibrate_says_which_between_session_component_it_used(tmp_path: Path, capsys) -> None:
    from robocal_uncertainty.bagio import write_campaign
    from robocal_uncertainty.cli import main

    model = dataclasses.replace(load_robot_model(DATA / "ur10.yaml"), base_known=False)
    first = simulate_sessions(model, SessionSimulationSettings(n_sessions=1, n_poses=25), seed=2).sessions[0]
    write_campaign(tmp_path / "s1.mcap", first.campaign)
    assert main(["calibrate", str(tmp_path / "s1.mcap"), "--robot", "ur10", "--class-prior", "ur10"]) == 0
    out = capsys.readouterr().out
    assert "statement scope: future sessions (between-session component from the class prior alone, 3+" in out
    assert "joint offsets 34.38 mdeg, length scale 340.0 ppm per session" in out  # 0.6 mrad, 3.4e-4
    assert "class prior shipped ur10 (robocal_uncertainty/data/ur10_between_sessions.yaml)" in out
    assert main(["calibrate", str(tmp_path / "s1.mcap"), "--robot", "ur10", "--class-prior", "nosuch"]) == 1
    assert "error: class prior nosuch: neither a shipped prior (ur10)" in capsys.readouterr().err
    # The UR10's prior is not another shipped robot's: refused in one line, not applied silently.
    assert main(["calibrate", str(tmp_path / "s1.mcap"), "--robot", "paper_arm", "--class-prior", "ur10"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--class-prior ur10 is the between-session prior of the ur10 class, not of --robot paper_arm" in err
