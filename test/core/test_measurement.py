"""The measurement seam: points unchanged, and other measurement types through the same loops.

* Points: the identification, observability, model-adequacy test and batched
  re-identification give the numbers they gave before the seam existed (reference computed on
  commit e639856 by ``measurement_reference.py``).
* Two toy types defined only here, a planar point (x and y of the tool, weighted by their
  stated uncertainties) and a distance to a fixed point (one equation per pose, nonlinear),
  identify through ``identify``, ``ChordSolver``, ``reidentify_batch`` and
  ``assess_model_adequacy`` without any change to them. Their Jacobians are checked against
  finite differences, the weighted fit against an independent scipy least-squares fit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from measurement_reference import compute
from numpy.typing import NDArray
from scipy.optimize import least_squares

from robocal_uncertainty.core.campaign import Campaign
from robocal_uncertainty.core.identification import identify
from robocal_uncertainty.core.kinematics import forward_points, forward_points_and_jacobian
from robocal_uncertainty.core.measurement import (
    POINT,
    MeasurementType,
    PointMeasurement,
    stack_equations,
)
from robocal_uncertainty.core.observability import structural_observability
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.robot_model import ParameterLayout, RobotModel
from robocal_uncertainty.core.simulation import (
    EncoderNoise,
    SimulationSettings,
    TrackerNoise,
    draw_joint_positions,
    simulate_campaign,
)
from robocal_uncertainty.errors import ConfigError, InputError
from robocal_uncertainty.uncertainty.model_adequacy import assess_model_adequacy
from robocal_uncertainty.uncertainty.reidentification import BatchProblem, ChordSolver, reidentify_batch

Array = NDArray[np.float64]
REPO = Path(__file__).resolve().parents[2]
REFERENCE = Path(__file__).resolve().parent / "data" / "measurement_reference.npz"
TRACKER_IN_BASE = np.array([2.0, 0.5, 0.3])


# --- toy measurement types, defined here only -------------------------------------------


@dataclass(frozen=True)
class PlanarPoint(MeasurementType):
    """x and y of the tool point [m], each weighted by its standard uncertainty."""

    std: tuple[float, float] = (5e-6, 10e-6)

    @property
    def name(self) -> str:
        return "planar point"

    @property
    def quantity(self) -> str:
        return "measured x, y"

    @property
    def dimension(self) -> int:
        return 2

    @property
    def value_size(self) -> int:
        return 2

    @property
    def component_names(self) -> tuple[str, ...]:
        return ("x", "y")

    @property
    def component_units(self) -> tuple[str, ...]:
        return ("m", "m")

    @property
    def weights(self) -> Array:
        return 1.0 / np.asarray(self.std)

    def predict(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> Array:
        return forward_points(layout, params, joint_positions)[..., :2]

    def predict_and_jacobian(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> tuple[Array, Array]:
        points, jac = forward_points_and_jacobian(layout, params, joint_positions)
        return points[..., :2], jac[..., :2, :]


@dataclass(frozen=True)
class Distance(MeasurementType):
    """Distance [m] from a fixed point (a single-beam interferometer at `origin`)."""

    origin: tuple[float, float, float] = (2.0, 0.5, 0.3)

    @property
    def name(self) -> str:
        return "distance"

    @property
    def quantity(self) -> str:
        return "measured distance"

    @property
    def dimension(self) -> int:
        return 1

    @property
    def value_size(self) -> int:
        return 1

    @property
    def component_names(self) -> tuple[str, ...]:
        return ("distance",)

    @property
    def component_units(self) -> tuple[str, ...]:
        return ("m",)

    def predict(self, layout: ParameterLayout, params: Array, joint_positions: Array) -> Array:
        points = forward_points(layout, params, joint_positions)
        return np.linalg.norm(points - np.asarray(self.origin), axis=-1, keepdims=True)

    def predict_and_jacobian(
        self, layout: ParameterLayout, params: Array, joint_positions: Array
    ) -> tuple[Array, Array]:
        points, jac = forward_points_and_jacobian(layout, params, joint_positions)
        offset = points - np.asarray(self.origin)
        dist = np.linalg.norm(offset, axis=-1, keepdims=True)
        unit = offset / dist
        return dist, np.einsum("...i,...ik->...k", unit, jac)[..., None, :]


TYPES: dict[str, MeasurementType] = {"point": POINT, "planar": PlanarPoint(), "distance": Distance()}


def paper() -> RobotModel:
    return load_robot_model(REPO / "config" / "paper_arm.yaml")


def toy_campaign(model: RobotModel, measurement: MeasurementType, n_poses: int, seed: int) -> tuple[Campaign, Array]:
    """Base-frame campaign of `measurement` on a simulated true robot; also the true parameters."""
    sim = simulate_campaign(model, SimulationSettings(n_poses=n_poses), seed=seed)
    true_params = sim.true_model.parameter_vector()
    rng = np.random.default_rng(seed + 7)
    exact = measurement.predict(model.layout, true_params, sim.true_joint_positions)
    std = np.asarray(getattr(measurement, "std", (5e-6,) * measurement.dimension))
    measured = measurement.perturb(exact, rng.normal(size=(n_poses, measurement.dimension)) * std)
    campaign = Campaign(
        joint_names=model.joint_names,
        joint_positions=sim.campaign.joint_positions,
        points=measured,
        measurement=measurement,
    )
    return campaign, true_params


# --- points: the numbers before the seam -------------------------------------------------


# Another numpy, BLAS or LAPACK (Humble's numpy 1.21, Jazzy's 1.26, the newest; BLAS threaded or
# not) sums in another order, so each number moves by rounding: about eps = 2.2e-16 relative to
# the numbers it is computed from, accumulated over sums of hundreds of terms and a few
# iterations. The tolerance is therefore absolute, FP_RELATIVE times the scale of those numbers,
# never relative to each element: a residual of 2e-8 m carries the rounding of the metre-sized
# coordinates it is the difference of. Measured: at most 2e-13 of that scale (numpy 1.21.5 with
# scipy 1.8.0, 1.26.4 with 1.11.4, 2.4.6; OpenBLAS with one or two threads).
FP_RELATIVE = 1e-11
COORDINATES_M = 3.0  # the two simulated campaigns' points lie within 2.7 m of the origin


def _rounding_scale(key: str, reference: np.lib.npyio.NpzFile) -> float:
    """Scale of the numbers ``reference[key]`` is computed from (its own units)."""
    if key.endswith("_residuals"):  # m: measured minus predicted coordinates
        return COORDINATES_M
    if key.endswith("_adequacy_cov"):  # m²: sums of products of two residuals, each as above
        residuals = reference[key.replace("_adequacy_cov", "_residuals")]
        return 2.0 * COORDINATES_M * float(np.max(np.abs(residuals)))
    values = reference[key]
    return float(np.nanmax(np.abs(values))) if values.size else 0.0


def test_point_numbers_are_those_before_the_measurement_seam() -> None:
    """Identification, observability, adequacy and re-identification as on commit e639856.

    On the machine that computed the reference they are bit-identical; the tolerance is the
    rounding another numpy or BLAS may bring (``FP_RELATIVE``).
    """
    reference = np.load(REFERENCE)
    now = compute()
    assert set(now) == set(reference.files)
    for key in reference.files:
        if reference[key].dtype.kind in "US":
            assert now[key].tolist() == reference[key].tolist(), key
        else:
            atol = FP_RELATIVE * _rounding_scale(key, reference)
            np.testing.assert_allclose(now[key], reference[key], rtol=0.0, atol=atol, err_msg=key)


def test_default_campaign_and_problem_use_unweighted_points() -> None:
    model = paper()
    campaign = simulate_campaign(model, SimulationSettings(n_poses=30), seed=4).campaign
    assert campaign.measurement is POINT
    assert (POINT.dimension, POINT.value_size, POINT.weights) == (3, 3, None)
    assert campaign.subset([0, 2]).measurement is POINT
    result = identify(model, campaign)
    assert result.measurement is POINT
    assert BatchProblem.from_calibration(result).measurement is POINT


# --- the contract, for every type ---------------------------------------------------------


@pytest.mark.parametrize("name", list(TYPES))
def test_jacobians_match_finite_differences(name: str) -> None:
    measurement = TYPES[name]
    model = paper()
    layout = model.layout
    rng = np.random.default_rng(3)
    q = draw_joint_positions(model, 7, rng=rng)
    params = model.parameter_vector() + rng.uniform(-1e-3, 1e-3, layout.size)
    values, jac = measurement.predict_and_jacobian(layout, params, q)
    assert values.shape == (7, measurement.value_size)
    assert jac.shape == (7, measurement.dimension, layout.size)
    np.testing.assert_array_equal(values, measurement.predict(layout, params, q))
    h = 1e-6
    for k in range(layout.size):
        step = np.zeros(layout.size)
        step[k] = h
        # residual(m, predict(p + dp)) ~ residual(m, predict(p)) - J dp, central differences
        plus = measurement.residual(values, measurement.predict(layout, params + step, q))
        minus = measurement.residual(values, measurement.predict(layout, params - step, q))
        np.testing.assert_allclose(-(plus - minus) / (2 * h), jac[..., k], atol=2e-8, err_msg=layout.names[k])
    jq = measurement.joint_jacobian(layout, params, q)
    assert jq.shape == (7, measurement.dimension, model.n_joints)
    for j in range(model.n_joints):
        step = np.zeros(q.shape)
        step[:, j] = h
        plus = measurement.predict(layout, params, q + step)
        minus = measurement.predict(layout, params, q - step)
        np.testing.assert_allclose(
            measurement.residual(plus, minus) / (2 * h), jq[..., j], atol=2e-8, err_msg=f"joint {j}"
        )


@pytest.mark.parametrize("name", list(TYPES))
def test_perturb_is_the_inverse_of_residual_and_batches_broadcast(name: str) -> None:
    measurement = TYPES[name]
    model = paper()
    rng = np.random.default_rng(5)
    q = draw_joint_positions(model, 4, rng=rng)
    params = model.parameter_vector() + rng.uniform(-1e-3, 1e-3, (3, model.layout.size))
    values, jac = measurement.predict_and_jacobian(model.layout, params, q)
    assert values.shape == (3, 4, measurement.value_size)
    assert jac.shape == (3, 4, measurement.dimension, model.layout.size)
    errors = rng.normal(scale=1e-5, size=(3, 4, measurement.dimension))
    np.testing.assert_allclose(measurement.residual(measurement.perturb(values, errors), values), errors, atol=1e-15)
    r, a = stack_equations(measurement, errors, jac)
    assert r.shape == (3, 4 * measurement.dimension)
    assert a.shape == (3, 4 * measurement.dimension, model.layout.size)


# --- other types identify through the same loops ----------------------------------------


def test_weighted_planar_points_identify_as_an_independent_weighted_least_squares() -> None:
    model = paper()
    measurement = PlanarPoint()
    campaign, true_params = toy_campaign(model, measurement, 120, seed=21)
    result = identify(model, campaign, lambda_=0.0)
    assert result.converged
    assert result.residuals.shape == (120, 2)
    # The observability analysis ran on the type's own (whitened) equations.
    obs = structural_observability(model, result.nominal, result.candidates, measurement=measurement)
    np.testing.assert_array_equal(obs.identifiable, result.estimated)

    est = np.flatnonzero(result.estimated)
    weights = np.tile(measurement.weights, campaign.n_poses)

    def whitened(p_est: Array) -> Array:
        p = result.nominal.copy()
        p[est] = p_est
        predicted = measurement.predict(model.layout, p, campaign.joint_positions)
        return measurement.residual(campaign.points, predicted).ravel() * weights

    fit = least_squares(
        whitened, result.nominal[est], x_scale=1.0 / result.column_scale[est], xtol=1e-15, ftol=1e-15, gtol=1e-15
    )
    scipy_estimate = result.nominal.copy()
    scipy_estimate[est] = fit.x
    # Same minimiser, compared where it matters: the predicted x, y at fresh poses.
    fresh = draw_joint_positions(model, 300, rng=np.random.default_rng(1))
    ours = measurement.predict(model.layout, result.estimate, fresh)
    theirs = measurement.predict(model.layout, scipy_estimate, fresh)
    truth = measurement.predict(model.layout, true_params, fresh)
    nominal = measurement.predict(model.layout, result.nominal, fresh)
    assert np.max(np.abs(ours - theirs)) < 1e-9
    assert np.sqrt(np.mean((ours - truth) ** 2)) < 0.02 * np.sqrt(np.mean((nominal - truth) ** 2))
    # The weights matter: an unweighted fit of the same data is a different estimate.
    unweighted = identify(model, dataclasses.replace(campaign, measurement=PlanarPoint(std=(1.0, 1.0))), lambda_=0.0)
    assert not np.allclose(unweighted.estimate, result.estimate, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["planar", "distance"])
def test_toy_types_run_through_reidentification_and_adequacy(name: str) -> None:
    measurement = TYPES[name]
    model = paper()
    n_poses = 240 if name == "distance" else 120
    campaign, _ = toy_campaign(model, measurement, n_poses, seed=31)
    result = identify(model, campaign)
    assert result.converged
    assert result.measurement is measurement
    assert result.residuals.shape == (n_poses, measurement.dimension)

    problem = BatchProblem.from_calibration(result)
    x_hat = problem.scaled_deviation(result.estimate)
    rng = np.random.default_rng(2)
    n_trials = 6
    std = np.asarray(getattr(measurement, "std", (5e-6,)))
    q = campaign.joint_positions[None] + rng.uniform(-2e-5, 2e-5, (n_trials, n_poses, model.n_joints))
    measured = measurement.perturb(
        campaign.points[None], rng.normal(size=(n_trials, n_poses, measurement.dimension)) * std
    )
    weights = (rng.random((n_trials, n_poses)) < 0.85).astype(np.float64)
    lambdas = np.full(n_trials, result.lambda_)
    exact, _ = reidentify_batch(problem, q, measured, weights, lambdas, x_hat, iterations=8, tolerance=1e-14)
    chord, _ = ChordSolver.at(problem, result.estimate, campaign.joint_positions).solve(
        q, measured, weights, lambdas, x_hat, max_iterations=12, relative_tolerance=1e-9
    )
    spread = np.linalg.norm(exact - x_hat, axis=1)
    assert np.all(spread > 0)
    # The chord fixed point differs from Gauss-Newton's by (J_t - J*)^T r: second order, ~1e-4 here.
    np.testing.assert_array_less(np.linalg.norm(chord - exact, axis=1), 1e-3 * spread)

    # The trial with all poses and the calibration's own data is the calibration itself.
    again, _ = reidentify_batch(
        problem, campaign.joint_positions, campaign.points[None], None, lambdas[:1], x_hat, iterations=4
    )
    np.testing.assert_allclose(again[0], x_hat, rtol=0, atol=1e-6 * np.linalg.norm(x_hat))

    # Noise stated as drawn (tracker 5 um per component, plus the simulated encoder noise):
    # an adequate model; dimensions follow the type.
    distances = np.linalg.norm(
        forward_points(model.layout, result.estimate, campaign.joint_positions) - TRACKER_IN_BASE, axis=1
    )
    adequacy = assess_model_adequacy(
        result, campaign.joint_positions, TrackerNoise(a=5e-6 * np.sqrt(3.0), b=0.0), EncoderNoise(), distances
    )
    assert adequacy.inadequacy_covariance.shape == (measurement.dimension,) * 2
    assert adequacy.draws.shape == (n_poses, measurement.dimension)
    if name == "distance":
        assert adequacy.adequate, adequacy.p_value


def test_campaign_checks_values_against_its_measurement_type() -> None:
    model = paper()
    q = np.zeros((4, model.n_joints))
    with pytest.raises(InputError, match=r"points must have shape \(4, 2\), got \(4, 3\)"):
        Campaign(joint_names=model.joint_names, joint_positions=q, points=np.zeros((4, 3)), measurement=PlanarPoint())
    with pytest.raises(InputError, match="measurement must be a MeasurementType, got str"):
        Campaign(joint_names=model.joint_names, joint_positions=q, points=np.zeros((4, 3)), measurement="point")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="point std must be three positive"):
        PointMeasurement(std=(1e-6, 0.0, 1e-6))
