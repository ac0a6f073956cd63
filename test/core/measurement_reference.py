"""Numbers the measurement seam must not change: computed by :func:`compute` on commit e639856.

``python test/core/measurement_reference.py OUT.npz`` writes them; ``test_measurement.py``
recomputes them with the current code and compares. Everything here calls only the modules the
seam touches (identification, observability, re-identification, model adequacy), with inputs
drawn from fixed seeds, so another module's change (e.g. how the Monte Carlo draws its
sources) cannot move these numbers.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.observability import structural_observability
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import (
    EncoderNoise,
    SimulationSettings,
    TrackerNoise,
    UnmodelledErrors,
    simulate_campaign,
)
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy
from robocal_uncertainty.uncertainty.reidentification import BatchProblem, ChordSolver, reidentify_batch

REPO = Path(__file__).resolve().parents[2]
N_TRIALS = 40


def compute() -> dict[str, np.ndarray]:
    """Identification, observability, adequacy and batched re-identification of two campaigns."""
    out: dict[str, np.ndarray] = {}
    base_model = load_robot_model(REPO / "config" / "paper_arm.yaml")
    for frame, seed in (("base", 1), ("tracker", 2)):
        model = base_model if frame == "base" else dataclasses.replace(base_model, base_known=False)
        settings = SimulationSettings(frame=frame, unmodelled=UnmodelledErrors(compliance=np.radians(0.002)))
        campaign = simulate_campaign(model, settings, seed=seed).campaign
        res = identify(model, campaign)
        key = frame
        out[f"{key}_estimate"] = res.estimate
        out[f"{key}_residuals"] = res.residuals
        out[f"{key}_std"] = res.linearized_std
        out[f"{key}_scalars"] = np.array(
            [
                res.lambda_,
                res.rms_before,
                res.max_before,
                res.rms_after,
                res.max_after,
                res.iterations,
                res.condition_number,
                res.effective_parameters,
            ]
        )
        out[f"{key}_singular_values"] = res.singular_values
        out[f"{key}_estimated"] = res.estimated.astype(np.float64)
        obs = structural_observability(model, res.nominal, res.candidates)
        out[f"{key}_identifiable"] = obs.identifiable.astype(np.float64)
        out[f"{key}_dependencies"] = np.array(obs.dependencies)
        if frame == "tracker":
            distances = np.linalg.norm(campaign.points, axis=1)
        else:
            distances = np.linalg.norm(campaign.points - np.array([2.0, 0.5, 0.3]), axis=1)
        ad = assess_model_adequacy(res, campaign.joint_positions, TrackerNoise(), EncoderNoise(), distances)
        out[f"{key}_adequacy_scalars"] = np.array([ad.chi2, ad.dof, ad.p_value, float(ad.adequate)])
        out[f"{key}_adequacy_cov"] = np.stack((ad.residual_covariance, ad.noise_covariance, ad.inadequacy_covariance))
        out[f"{key}_adequacy_draws"] = ad.draws
        est = np.flatnonzero(res.estimated)
        scale = res.column_scale[est]
        problem = BatchProblem(model.layout, res.nominal, est, scale, res.penalized[est])
        x_hat = (res.estimate[est] - res.nominal[est]) * scale
        rng = np.random.default_rng(seed + 100)
        n = campaign.n_poses
        q = campaign.joint_positions[None] + rng.uniform(-1e-4, 1e-4, size=(N_TRIALS, n, model.n_joints))
        pts = campaign.points[None] + rng.uniform(-2e-5, 2e-5, size=(N_TRIALS, n, 3))
        weights = (rng.random((N_TRIALS, n)) < 0.8).astype(np.float64)
        lambdas = res.lambda_ * rng.uniform(0.5, 2.0, size=N_TRIALS)
        solver = ChordSolver.at(problem, res.estimate, campaign.joint_positions)
        out[f"{key}_chord_normal"] = solver.normal
        # The chord method as it was then: the first step from the exact prediction (the
        # first-order start of today's default is checked against converged solutions in
        # test/uncertainty/test_calibration_mc.py).
        out[f"{key}_chord_q"], _ = solver.solve(q, pts, None, lambdas, x_hat, linear_start=False)
        out[f"{key}_chord_qw"], _ = solver.solve(q, pts, weights, lambdas, x_hat, linear_start=False)
        fitted = campaign.points - res.residuals
        out[f"{key}_chord_fixed_q"], _ = solver.solve(
            campaign.joint_positions, pts, None, lambdas, x_hat, initial_prediction=fitted, linear_start=False
        )
        out[f"{key}_gn"], _ = reidentify_batch(problem, q, pts, weights, lambdas, x_hat, iterations=4)
    return out


if __name__ == "__main__":
    np.savez_compressed(sys.argv[1], **compute())
