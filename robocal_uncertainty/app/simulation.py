"""The simulation service: a simulated campaign MCAP and its ground truth beside it.

:func:`simulate` draws a true robot, poses and noisy measurements
(:func:`~robocal_uncertainty.core.simulation.simulate_campaign`), writes the campaign
MCAP and the truth as JSON (:data:`TRUTH_FORMAT`, SI units) in ``<campaign>.truth.json``.
Both output paths are checked before anything is drawn or written.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robocal_uncertainty.app.output_paths import check_output_file
from robocal_uncertainty.bagio.campaign_mcap import write_campaign
from robocal_uncertainty.bagio.raw_bag_simulator import RawBagSettings, RawBagTruth, write_raw_bag
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.simulation import (
    SessionSimulationSettings,
    SimulatedCampaign,
    SimulatedSessions,
    SimulationSettings,
    simulate_campaign,
    simulate_sessions,
)

__all__ = [
    "SESSION_TRUTH_FORMAT",
    "TRUTH_FORMAT",
    "RawRecordingFiles",
    "SessionFiles",
    "SimulationFiles",
    "session_path",
    "simulate",
    "simulate_raw_recording_file",
    "simulate_sessions_files",
    "simulation_truth",
    "truth_path",
]

TRUTH_FORMAT = "robocal_uncertainty/simulation_truth/1"
"""``format`` field of the truth JSON."""


@dataclass(frozen=True, eq=False)
class SimulationFiles:
    """What :func:`simulate` wrote: the campaign MCAP, the truth JSON and the simulation."""

    campaign_path: Path
    truth_path: Path
    simulation: SimulatedCampaign


def truth_path(campaign_path: str | Path) -> Path:
    """The truth file of a campaign file: the same name with the suffix ``.truth.json``."""
    return Path(campaign_path).with_suffix(".truth.json")


def simulation_truth(sim: SimulatedCampaign, nominal: RobotModel, *, seed: int | None) -> dict[str, Any]:
    """The truth of `sim` as a JSON-ready dict (lengths [m], angles [rad])."""
    settings = sim.settings
    return {
        "format": TRUTH_FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "robot": nominal.name,
        "seed": seed,
        "frame": settings.frame,
        "parameter_names": list(nominal.layout.names),
        "true_parameters": sim.true_model.parameter_vector().tolist(),
        "nominal_parameters": nominal.parameter_vector().tolist(),
        "true_joint_positions_rad": sim.true_joint_positions.tolist(),
        "true_points_m": sim.true_points.tolist(),
        "tracker_noise_a_m": settings.tracker_noise.a,
        "tracker_noise_b_m_per_m": settings.tracker_noise.b,
        "encoder_noise_half_width_rad": settings.encoder_noise.half_width,
    }


def simulate(
    model: RobotModel,
    settings: SimulationSettings,
    out: str | Path,
    *,
    seed: int | None,
    overwrite: bool = False,
) -> SimulationFiles:
    """Simulate a campaign of `model` and write it to `out` with its truth beside it.

    Parameters
    ----------
    model : RobotModel
        Nominal model; the truth is nominal plus uniform errors.
    settings : SimulationSettings
    out : str or Path
        Campaign MCAP to write; the truth goes to :func:`truth_path` of it.
    seed : int or None
        Seed of the simulation (recorded in the truth).
    overwrite : bool
        Replace existing files (the command line's ``--force``).

    Raises
    ------
    ConfigError
        An output file exists (without `overwrite`) or cannot be written.
    """
    campaign_path = check_output_file(out, force=overwrite, option="--out")
    truth = check_output_file(truth_path(campaign_path), force=overwrite, option="truth file")
    sim = simulate_campaign(model, settings, seed=seed)
    write_campaign(campaign_path, sim.campaign, overwrite=overwrite)
    truth.write_text(json.dumps(simulation_truth(sim, model, seed=seed), indent=1) + "\n", encoding="utf-8")
    return SimulationFiles(campaign_path=campaign_path, truth_path=truth, simulation=sim)


@dataclass(frozen=True, eq=False)
class RawRecordingFiles:
    """What :func:`simulate_raw_recording_file` wrote: the raw recording, the truth JSON, the
    simulation and the recording's own truth (its static windows, also in the file)."""

    recording_path: Path
    truth_path: Path
    simulation: SimulatedCampaign
    recording: RawBagTruth


def simulate_raw_recording_file(
    model: RobotModel,
    settings: SimulationSettings,
    recording: RawBagSettings,
    out: str | Path,
    *,
    seed: int,
    overwrite: bool = False,
) -> RawRecordingFiles:
    """Simulate a campaign of `model` and write it as a raw recording, the truth beside it.

    The recording is what a robot and a tracker publish during a campaign: joint states and
    tracker points (or poses) streamed at their rates while the arm moves from pose to pose and
    dwells at each, with stamp jitter, latency and beam dropouts. It is the input of ``replay``
    and of the collector node (``ros2 bag play``), so a campaign's processing can be rehearsed
    before the robot is measured, against a known truth.

    Parameters
    ----------
    model : RobotModel
        Nominal model; the truth is nominal plus uniform errors.
    settings : SimulationSettings
        The simulated campaign (poses, frame, noise).
    recording : RawBagSettings
        Rates [Hz], dwell and move times [s] and the streams' imperfections.
    out : str or Path
        MCAP file to write; the campaign's truth goes to :func:`truth_path` of it.
    seed : int
        Seed of the simulation and of the recording's timing and noise (recorded in both).
    overwrite : bool
        Replace existing files (the command line's ``--force``).

    Raises
    ------
    ConfigError
        An output file exists (without `overwrite`) or cannot be written.
    """
    path = check_output_file(out, force=overwrite, option="--out")
    truth = check_output_file(truth_path(path), force=overwrite, option="truth file")
    sim = simulate_campaign(model, settings, seed=seed)
    raw_truth = write_raw_bag(path, sim, recording, seed=seed, overwrite=overwrite)
    truth.write_text(json.dumps(simulation_truth(sim, model, seed=seed), indent=1) + "\n", encoding="utf-8")
    return RawRecordingFiles(recording_path=path, truth_path=truth, simulation=sim, recording=raw_truth)


SESSION_TRUTH_FORMAT = "robocal_uncertainty/session_truth/1"
"""``format`` field of a session's truth JSON."""


@dataclass(frozen=True, eq=False)
class SessionFiles:
    """What :func:`simulate_sessions_files` wrote: one campaign and truth per session."""

    campaign_paths: tuple[Path, ...]
    truth_paths: tuple[Path, ...]
    simulation: SimulatedSessions


def session_path(out: str | Path, index: int) -> Path:
    """Campaign path of session `index` (1-based): ``run.mcap`` -> ``run.session2.mcap``."""
    path = Path(out)
    return path.with_name(f"{path.stem}.session{index}{path.suffix or '.mcap'}")


def simulate_sessions_files(
    model: RobotModel,
    settings: SessionSimulationSettings,
    out: str | Path,
    *,
    seed: int | None,
    overwrite: bool = False,
) -> SessionFiles:
    """Simulate several sessions of one robot; write each campaign and its truth.

    Session ``k`` goes to :func:`session_path` ``(out, k)`` with its truth beside it
    (:func:`truth_path`): the robot (shared), the session's true parameters (its tracker frame
    as the base), its tracker placement, probe remount, joint-offset drift and temperature
    (format :data:`SESSION_TRUTH_FORMAT`, SI units). Every output path is checked before
    anything is drawn or written.
    """
    paths = [session_path(out, k + 1) for k in range(settings.n_sessions)]
    campaigns = [check_output_file(p, force=overwrite, option="--out") for p in paths]
    truths = [check_output_file(truth_path(p), force=overwrite, option="truth file") for p in campaigns]
    sim = simulate_sessions(model, settings, seed=seed)
    for k, (campaign_path, truth, session, change) in enumerate(zip(campaigns, truths, sim.sessions, sim.changes)):
        write_campaign(campaign_path, session.campaign, overwrite=overwrite)
        data = simulation_truth(session, model, seed=seed)
        data.update(
            {
                "format": SESSION_TRUTH_FORMAT,
                "session": k + 1,
                "n_sessions": settings.n_sessions,
                "robot_parameters": sim.robot_parameters.tolist(),
                "change": change.to_dict(),
                "expansion_per_K": settings.expansion,
            }
        )
        truth.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return SessionFiles(campaign_paths=tuple(campaigns), truth_paths=tuple(truths), simulation=sim)
