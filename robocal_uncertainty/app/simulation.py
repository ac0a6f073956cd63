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
from robocal_uncertainty.core.robot_model import RobotModel
from robocal_uncertainty.core.simulation import SimulatedCampaign, SimulationSettings, simulate_campaign

__all__ = ["TRUTH_FORMAT", "SimulationFiles", "simulate", "simulation_truth", "truth_path"]

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
