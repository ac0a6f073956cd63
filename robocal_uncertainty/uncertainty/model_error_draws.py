"""The model error every statement draws: one Gaussian field over configurations.

What the kinematic model cannot represent (gear errors, compliance, thermal gradients) is a
smooth function of the joint configuration. ``verify`` already states it as the Gaussian field
of :mod:`~robocal_uncertainty.core.model_error_field`; drawing it independently from pose to
pose instead (the residual bootstrap) states the same calibration another way: an error that
is smooth over the workspace is treated as one that averages out, and what the fit absorbed of
it at its poses is counted again at every test configuration.

With ``model_error="field"`` (the default; ``--independent-model-error`` for the residual
bootstrap, see the README's held-out study) the ``residual`` source draws the field **jointly**
over the calibration poses and the test configurations: ``e_t`` is added to the measured values
(the re-fit absorbs part of it, as the calibration did) and ``-e_c`` to the predictions, so a
trial's deviation is
``J G e_t - e_c``, whose covariance is that of the real prediction error ``e_c - J G e_t``
(``G`` the fit's gain): the cross term ``J G K_tc`` that ``verify`` subtracts analytically, by
construction. The GUM statement propagates the covariance of the same vector.

The field's covariance is a scalar correlation over configurations times one per-pose
covariance ``Sigma_m`` (``d x d``, the measurement's residual coordinates), so every draw is a
product of a scalar factor and ``Sigma_m^(1/2)``. Calibration poses are drawn through the
Cholesky factor ``L`` of their correlation ``C_tt = c R_tt + (1 - c) I``; the test
configurations conditionally on them, ``e_c = B z_t + D^(1/2) z_c`` with ``B = c R_ct L^-T``
and ``D = C_cc - B B^T``: jointly (a Cholesky factor of ``D``) up to :data:`JOINT_TEST_MAX`
configurations, beyond (a workspace map's thousands) with the diagonal of ``D`` only, so each
configuration's marginal (and its correlation with the calibration poses) is exact and memory
grows as ``n_c n_t``, never ``n_c^2``.

The correlation (``c``, ``l``) comes from restricted maximum likelihood on the calibration's own
residuals, whitened by the measurement type's weights (points and 6-DOF poses alike); the
per-pose covariance ``Sigma_m = diag(f) S diag(f)`` (``S`` the shape of the residuals'
covariance) from their leave-one-out prediction errors, component by component: the spread a
prediction at a configuration the fit did not see has, which a misstated kernel cannot make too
small. Where one covariance fits everywhere the draws resample the standardised residuals (the
field's covariance, the residuals' distribution).

That scale is an estimate: a smooth error is seen by a few independent patches of the
workspace, so a 53-pose campaign fixes it with 15-40 effective degrees of freedom
(Satterthwaite under the fitted field, fewer for heavy tails), and a statement that plugs it in
as known is too narrow, most visibly in the joint (JCGM 102) region of several components. The
draws therefore take the scale as uncertain as its estimate: per draw and component a factor
``sqrt(nu_j / chi2(nu_j))`` (Student-t marginals, the predictive distribution of a normal
quantity with an estimated variance, JCGM 101 6.4.9), and the GUM propagates the covariance of
the same draws. A field whose scale has fewer than :data:`MIN_SCALE_DOF` degrees of freedom in a
component is not drawn: the residual source then draws the independent model error.

One per-pose covariance for the whole workspace is right on average per axis but not jointly:
a real model error is larger, and differently shaped, in some regions than in others (on the
UR10 series D the local correlation between two axes ranges from -0.5 to 0.5), so its errors
whitened by one covariance are heavier tailed jointly than a normal's, and a JCGM 102 region of
several components drawn with one covariance is too small even where every axis holds. The
draws give every configuration a local covariance ``Sigma_m^(1/2) W Sigma_m^(1/2)``, ``W``
Wishart with mean ``I`` (the covariance, and with it the GUM statement, unchanged). How much it
varies (``tau = d / k``) is a hyperparameter that a small campaign determines poorly (a sample
kurtosis of heavy-tailed errors is biased low: plugged in it gives back little of the
variation), so each draw takes ``tau`` from its posterior given the leave-one-out prediction
errors (:func:`_shape_posterior`).

The correlation (``c``, ``l``) is a hyperparameter of the same kind: a few tens of poses leave the
length to within a factor of several (the likelihood's maximum can lie at the end of the range),
so the draws take it from its posterior as well (:func:`_hyper_posterior`), each hypothesis with
the leave-one-out scale it implies. The scale's degrees of freedom take with them a local
variance that varies over the workspace as the error does (:func:`_leave_one_out_dof`), and the
components' scale factors share the common local scale the leave-one-out errors show
(:func:`_scale_correlation`). No constant is tuned to a data set.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.identification import IdentificationResult
from robocal_uncertainty.core.measurement import row_weights
from robocal_uncertainty.core.model_error_field import FIELD_KERNEL, FIELD_METRIC, chordal_distance, kernel_correlation
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.model_adequacy import MIN_RESIDUAL_DOF_PER_COMPONENT

__all__ = [
    "FIELD_LENGTH_BOUNDS",
    "FIELD_MAX_EQUATIONS",
    "JOINT_TEST_MAX",
    "MIN_SCALE_DOF",
    "FieldEstimate",
    "FieldNormal",
    "central_hessian",
    "estimate_field",
    "rescaled_field",
    "standardised_innovations",
]

Array = NDArray[np.float64]
FIELD_MAX_EQUATIONS = 600
"""Most residual equations the hyperparameters are estimated from (a seeded subset of the poses
of larger campaigns: 200 point poses, 100 6-DOF poses); the likelihood costs a Cholesky
factorisation of this size per evaluation."""
JOINT_TEST_MAX = 1024
"""Test configurations up to which their model errors are drawn jointly (their correlation kept);
beyond, each conditionally on the calibration poses alone (exact per-configuration marginals)."""
FIELD_LENGTH_BOUNDS = (0.02, 20.0)
"""Range [rad] of the field's correlation length searched by the likelihood (shared with the
session field of :mod:`.sessions`)."""
_JITTER = 1e-10
MIN_SCALE_DOF = 4.0
"""Fewest effective degrees of freedom of a component's scale for the field to be drawn (a
Student-t with ``nu <= 4`` has no finite fourth moment)."""
_T_DOF_MAX = 1e6
"""Beyond these degrees of freedom the scale is drawn as known (the t is the normal)."""
SHAPE_TAU = np.linspace(0.0, 1.0, 17)
"""Grid of ``tau = d / k`` (``k`` the Wishart degrees of freedom of the local per-pose covariance,
``d`` its dimension): 0 (one covariance over the whole workspace) to 1 (``k = d``, the fewest
for which the local covariance is non-singular). The prior is uniform on it: the excess
kurtosis of the errors (``2 / k``) is linear in ``tau``."""
SHAPE_DRAWS = 2000
"""Wishart draws of the Monte Carlo integral of the mixture's density (common random numbers
over the grid, seeded)."""
HYPER_FRACTIONS = np.linspace(0.1, 0.9, 5)
"""Grid of the correlated fraction ``c`` (cell centres of [0, 1]; uniform prior) over which the
restricted likelihood is integrated (:func:`_hyper_posterior`)."""
HYPER_LENGTHS = np.exp(
    np.log(FIELD_LENGTH_BOUNDS[0]) + (np.arange(8) + 0.5) * np.log(FIELD_LENGTH_BOUNDS[1] / FIELD_LENGTH_BOUNDS[0]) / 8
)
"""Grid of the correlation length ``l`` [rad] (cell centres of the searched range in ``log l``;
prior uniform in ``log l``, the scale-free prior of a length)."""
HYPER_DRAWS = 8
"""Hypotheses ``(c, l)`` the posterior is represented by in the draws (systematic resampling of
the grid, seeded; each carries its own leave-one-out scale)."""


@dataclass(frozen=True, eq=False)
class FieldHypothesis:
    """One ``(c, l)`` of the posterior of the field's correlation, with the scale it implies.

    Attributes
    ----------
    weight : float
        Its share of the draws (posterior probability; the weights of an estimate sum to 1).
    correlated_fraction : float
    length_scale : float [rad]
    per_pose_covariance : ndarray, shape (d, d)
        The leave-one-out per-pose covariance under this correlation (what the fit absorbs, and
        with it the scale that explains the prediction errors, depends on it).
    scale_dof : ndarray, shape (d,)
        Effective degrees of freedom of that scale, per component.
    """

    weight: float
    correlated_fraction: float
    length_scale: float
    per_pose_covariance: Array
    scale_dof: Array

    def to_dict(self) -> dict[str, object]:
        return {
            "weight": float(self.weight),
            "correlated_fraction": float(self.correlated_fraction),
            "length_scale_rad": float(self.length_scale),
            "standard_uncertainty": np.sqrt(np.clip(np.diag(self.per_pose_covariance), 0.0, None)).tolist(),
            "scale_dof": np.asarray(self.scale_dof).tolist(),
        }


@dataclass(frozen=True, eq=False)
class FieldEstimate:
    """The model-error field of a calibration, in its measurement's residual coordinates.

    Attributes
    ----------
    correlated_fraction : float
        ``c`` in [0, 1] (0: independent from pose to pose).
    length_scale : float [rad]
        ``l`` of the exponential kernel over the chordal joint distance.
    per_pose_covariance : ndarray, shape (d, d) [m^2; rad^2 for rotation components]
        ``Sigma_m``: the model error's covariance at one configuration, measurement frame (its
        scale from the leave-one-out prediction errors, see :func:`estimate_field`).
    likelihood_per_pose_covariance : ndarray, shape (d, d), or None
        The same with the restricted-likelihood scale (recorded for comparison).
    log_likelihood, independent_log_likelihood : float
        Restricted log-likelihood at the estimate and of the best ``c = 0`` model.
    dof : float
        Effective degrees of freedom of the scale (``2 / var(log s)`` from the curvature).
    poses_used : int
        Poses the hyperparameters were estimated from.
    scale_dof : ndarray, shape (d,), or None
        ``nu_j``: effective degrees of freedom of each component's leave-one-out scale
        (:func:`_leave_one_out_dof`); the draws take its uncertainty with them.
    shape_weights : ndarray, shape (len(SHAPE_TAU),), or None
        Posterior probabilities of the per-pose covariance's variation over the workspace,
        ``tau = 1 / k`` on the grid :data:`SHAPE_TAU` (``k`` the Wishart degrees of freedom of the
        local covariance about ``Sigma_m``; ``tau = 0``: one covariance everywhere), from the
        leave-one-out prediction errors (:func:`_shape_posterior`). The draws take ``tau`` from it
        (None: one covariance everywhere).
    hyper_covariance : ndarray, shape (3, 3)
        Covariance of the estimates of ``(log s, c, log l)`` (``s`` the likelihood's scale),
        the inverse curvature of the restricted likelihood; zero rows for those at a bound.
    contrasts : int
        Residual equations orthogonal to the fit the likelihood is made of.
    scale_correlation : float
        Correlation in [0, 1) of the components' scale estimates (:func:`_scale_correlation`);
        the draws' scale factors share it (0: independent per component).
    hypotheses : tuple of FieldHypothesis, or None
        The posterior of the correlation ``(c, l)`` the draws take it from, a hypothesis per draw
        (:func:`_hyper_posterior`); None: the draws plug in ``c``, ``l`` and
        :attr:`per_pose_covariance` above (the restricted-likelihood estimate, recorded either way).
    """

    correlated_fraction: float
    length_scale: float
    per_pose_covariance: Array
    likelihood_per_pose_covariance: Array | None = None
    log_likelihood: float = float("nan")
    independent_log_likelihood: float = float("nan")
    dof: float = float("inf")
    poses_used: int = 0
    kernel: str = FIELD_KERNEL
    metric: str = FIELD_METRIC
    scale_dof: Array | None = None
    shape_weights: Array | None = None
    hyper_covariance: Array = field(default_factory=lambda: np.zeros((3, 3)))
    contrasts: int = 0
    hypotheses: tuple[FieldHypothesis, ...] | None = None
    scale_correlation: float = 0.0

    @property
    def identified(self) -> bool:
        """Whether the field's per-component scale is determined well enough to state it.

        The statement takes the scale from the leave-one-out prediction errors and draws its
        uncertainty (``nu_j``, :attr:`scale_dof`) with it (:class:`FieldNormal`: a Student-t
        predictive distribution per component), so a scale from few effective degrees of
        freedom widens the statement by what it is uncertain, instead of being refused or stated
        as known. A scale with ``nu_j <`` :data:`MIN_SCALE_DOF` (the t's fourth moment, and with it
        the spread of its own variance, is infinite) is not drawn: the residual source then draws
        the independent model error (the field's ``c = 0`` case). Without :attr:`scale_dof`
        (an estimate made elsewhere) the likelihood's ``dof >= 32`` (the project's one-variance
        rule, :data:`~robocal_uncertainty.uncertainty.model_adequacy.MIN_RESIDUAL_DOF_PER_COMPONENT`).
        """
        if self.scale_dof is None:
            return bool(self.dof >= MIN_RESIDUAL_DOF_PER_COMPONENT)
        return bool(np.all(np.asarray(self.scale_dof) >= MIN_SCALE_DOF))

    @property
    def shape_dof(self) -> float | None:
        """``1 / E[tau]`` of :attr:`shape_weights`: the Wishart degrees of freedom of the local
        per-pose covariance the draws have on average (None: one covariance everywhere)."""
        if self.shape_weights is None:
            return None
        mean_tau = float(np.asarray(self.shape_weights) @ SHAPE_TAU)
        return None if mean_tau <= 0.0 else float(self.per_pose_covariance.shape[0]) / mean_tau

    @property
    def standard_uncertainty(self) -> Array:
        """Per-component standard uncertainty of the model error at one configuration, shape (d,)."""
        return np.sqrt(np.clip(np.diag(self.per_pose_covariance), 0.0, None))

    def describe(self) -> str:
        """One line for the console: how the residual source draws the model error."""
        fu = self.standard_uncertainty
        text = f"({', '.join(f'{v * 1e6:.1f}' for v in fu[:3])}) um"
        if len(fu) > 3:
            text = f"position {text}, rotation ({', '.join(f'{v * 1e6:.1f}' for v in fu[3:])}) urad"
        dof = "" if self.scale_dof is None else ", ".join(f"{v:.0f}" for v in np.asarray(self.scale_dof))
        if not self.identified:
            why = (
                f"its scale has ({dof}) effective degrees of freedom, fewer than {MIN_SCALE_DOF:.0f}"
                if self.scale_dof is not None
                else f"{self.dof:.0f} effective degrees of freedom, fewer than {MIN_RESIDUAL_DOF_PER_COMPONENT:.0f}"
            )
            head = "drawn independently from pose to pose: the correlated field is not identified by these poses"
            return f"{head} ({why})"
        scale = "" if self.scale_dof is None else f", its scale's uncertainty drawn with it ({dof} degrees of freedom)"
        k = self.shape_dof
        if k is not None:
            scale += f", its shape varying over the workspace (Wishart, {k:.0f} degrees of freedom on average)"
        if self.hypotheses is not None and len(self.hypotheses) > 1:
            lengths = [h.length_scale for h in self.hypotheses]
            scale += (
                f", its correlation drawn from its posterior ({len(self.hypotheses)} hypotheses, "
                f"length {min(lengths):.2f}-{max(lengths):.2f} rad)"
            )
        return (
            f"drawn as a field over the joint configurations (restricted maximum likelihood): u = {text}, "
            f"{self.correlated_fraction * 100:.0f} % correlated over {self.length_scale:.2f} rad, jointly over the "
            f"calibration poses and the test configurations{scale}"
        )

    def to_dict(self) -> dict[str, object]:
        """JSON-ready record (reports, ``calibrate --json``)."""
        return {
            "kernel": self.kernel,
            "metric": self.metric,
            "correlated_fraction": float(self.correlated_fraction),
            "length_scale_rad": float(self.length_scale),
            "per_pose_covariance": self.per_pose_covariance.tolist(),
            "standard_uncertainty": self.standard_uncertainty.tolist(),
            "likelihood_standard_uncertainty": None
            if self.likelihood_per_pose_covariance is None
            else np.sqrt(np.clip(np.diag(self.likelihood_per_pose_covariance), 0.0, None)).tolist(),
            "log_likelihood": float(self.log_likelihood),
            "independent_log_likelihood": float(self.independent_log_likelihood),
            "dof": float(self.dof),
            "identified": self.identified,
            "poses_used": int(self.poses_used),
            "scale_dof": None if self.scale_dof is None else np.asarray(self.scale_dof).tolist(),
            "shape_tau": None if self.shape_weights is None else SHAPE_TAU.tolist(),
            "shape_weights": None if self.shape_weights is None else np.asarray(self.shape_weights).tolist(),
            "shape_dof": self.shape_dof,
            "scale_correlation": float(self.scale_correlation),
            "hypotheses": None if self.hypotheses is None else [h.to_dict() for h in self.hypotheses],
        }


def central_hessian(fun: Callable[[Array], float], x0: Array, free: list[int], step: float = 1e-3) -> Array:
    """Central-difference Hessian of `fun` at `x0` over the coordinates `free`."""
    hess = np.empty((len(free), len(free)))
    for a, i in enumerate(free):
        for b, j in enumerate(free):
            values = []
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                x = x0.copy()
                x[i] += si * step
                x[j] += sj * step
                values.append(fun(x))
            hess[a, b] = (values[0] - values[1] - values[2] + values[3]) / (4 * step * step)
    return hess


def estimate_field(
    calibration: IdentificationResult,
    joint_positions: Array,
    noise: Array,
    shape: Array,
    *,
    max_equations: int = FIELD_MAX_EQUATIONS,
    seed: int = 0,
    leave_one_out: bool = True,
    correlation_posterior: bool = True,
) -> FieldEstimate:
    """The model-error field of a calibration by restricted maximum likelihood.

    The residuals' projection on the directions orthogonal to the (whitened) Jacobian depends
    neither on the parameters nor on their estimate and is normal with covariance
    ``Q^T W (N + V(s, c, l)) W Q`` (``N`` the stated noise, ``V = [c rho(d / l) + (1 - c) I]
    (x) s S``, ``W`` the measurement type's whitening weights); ``s``, ``c``, ``l`` maximise its
    likelihood (Harville's identity, ``Q`` never formed). ``c = 0`` is the independent model
    error; for points it is the estimator of
    :func:`~robocal_uncertainty.uncertainty.sessions.field.estimate_model_error_field`. The returned
    per-pose covariance keeps ``c`` and ``l`` and takes its scale, per component, from the
    leave-one-out prediction errors (:func:`_leave_one_out_scale`,
    :func:`_leave_one_out_components`); the likelihood's is recorded beside it.

    Parameters
    ----------
    calibration : IdentificationResult
    joint_positions : ndarray, shape (n, n_joints) [rad]
    noise : ndarray, shape (n, d, d)
        Stated noise covariance per pose, residual coordinates (unweighted).
    shape : ndarray, shape (d, d)
        Shape ``S`` of the per-pose model-error covariance (its scale is estimated).
    max_equations : int
        Campaigns with more residual equations use a seeded subset of their poses.
    seed : int
        Seed of that subset.
    leave_one_out : bool
        False: the per-pose covariance is the likelihood's (``verify``'s session field, whose
        checks re-register and test against the validated level), without the leave-one-out
        scale and its degrees of freedom.
    correlation_posterior : bool
        False: no :attr:`~FieldEstimate.hypotheses` (the draws plug in the restricted-likelihood
        correlation; for checks of the estimate itself).
    """
    system = _field_system(calibration, joint_positions, noise, shape, max_equations=max_equations, seed=seed)
    fun, log_s, c, log_l, independent_fun, bounds = _reml_optimum(system)
    r, fit, n_cov, d = system.residuals, system.fit, system.noise, system.dimension
    m = r.size - fit.shape[1]
    hyper, dof = _hyper_covariance(system, log_s, c, log_l)
    const = 0.5 * m * np.log(2 * np.pi)
    common = {
        "correlated_fraction": float(c),
        "length_scale": float(np.exp(log_l)),
        "likelihood_per_pose_covariance": float(np.exp(log_s)) * system.shape,
        "log_likelihood": -fun - const,
        "independent_log_likelihood": -independent_fun - const,
        "dof": float(min(max(dof, 1.0), m)),
        "poses_used": int(system.poses),
        "hyper_covariance": hyper,
        "contrasts": int(m),
    }
    if not leave_one_out:
        return FieldEstimate(per_pose_covariance=float(np.exp(log_s)) * system.shape, **common)
    unit = system.unit_covariance(c, float(np.exp(log_l)))
    scale = _leave_one_out_scale(r, fit, n_cov, unit, d, (float(np.exp(bounds[0])), float(np.exp(bounds[1]))))
    if scale is None:  # no scale explains the prediction errors (a degenerate shape): the likelihood's
        scale = float(np.exp(log_s))
    factors = _leave_one_out_components(r, fit, n_cov, unit, d, scale)
    scale_dof, white, n_eff = _leave_one_out_dof(r, fit, n_cov, unit, d, factors)
    shape_weights = _shape_posterior(white, n_eff, seed)
    # The shape's variation is a local variance varying over the workspace (W_jj of the Wishart:
    # variance 2 / k = 2 tau / d), which the scale's degrees of freedom take with them where the
    # sample kurtosis of a few tens of errors (biased low) shows less.
    local_variance = 2.0 * float(shape_weights @ SHAPE_TAU) / d
    scale_dof = _leave_one_out_dof(r, fit, n_cov, unit, d, factors, local_variance=local_variance)[0]
    hypotheses = []
    for weight, c_h, l_h, log_s_h in _hyper_posterior(system, log_s, seed) if correlation_posterior else []:
        unit_h = system.unit_covariance(c_h, l_h)
        scale_h = _leave_one_out_scale(r, fit, n_cov, unit_h, d, (float(np.exp(bounds[0])), float(np.exp(bounds[1]))))
        factors_h = _leave_one_out_components(
            r, fit, n_cov, unit_h, d, float(np.exp(log_s_h)) if scale_h is None else scale_h
        )
        dof_h = _leave_one_out_dof(r, fit, n_cov, unit_h, d, factors_h, local_variance=local_variance)[0]
        hypotheses.append(
            FieldHypothesis(weight, c_h, l_h, system.shape * np.outer(factors_h, factors_h), np.asarray(dof_h))
        )
    return FieldEstimate(
        per_pose_covariance=system.shape * np.outer(factors, factors),
        scale_dof=scale_dof,
        shape_weights=shape_weights,
        hypotheses=tuple(hypotheses) if correlation_posterior else None,
        scale_correlation=_scale_correlation(white),
        **common,
    )


def rescaled_field(
    held: FieldEstimate,
    calibration: IdentificationResult,
    joint_positions: Array,
    noise: Array,
    shape: Array,
    *,
    max_equations: int = FIELD_MAX_EQUATIONS,
    seed: int = 0,
) -> FieldEstimate:
    """The field of `calibration` with the correlation and shape hyperparameters of `held` (another
    calibration's :func:`estimate_field` of the same robot and poses), its per-pose covariance re-estimated.

    For a sensitivity sweep (a calibration re-identified at another lambda): the correlation
    ``(c, l)``, its posterior's hypotheses and weights, the shape's variation over the workspace and
    the components' scale correlation are what the robot's model error is, which a setting of the
    fit does not change; the per-component scale and its degrees of freedom are what this
    calibration's leave-one-out prediction errors show (the fit's regularisation changes what it
    absorbs), as :func:`estimate_field` takes them, per hypothesis. The restricted likelihood and
    its posterior grid are not evaluated again (most of the cost of an estimate).

    Parameters
    ----------
    held : FieldEstimate
        With leave-one-out scales (:attr:`FieldEstimate.scale_dof` not None).
    calibration, joint_positions, noise, shape, max_equations, seed
        As for :func:`estimate_field`.
    """
    system = _field_system(calibration, joint_positions, noise, shape, max_equations=max_equations, seed=seed)
    r, fit, n_cov, d = system.residuals, system.fit, system.noise, system.dimension
    _, lo_s, hi_s = _scale_start_and_bounds(system)
    bounds = (float(np.exp(lo_s)), float(np.exp(hi_s)))
    held_scale = float(
        np.trace(
            held.likelihood_per_pose_covariance
            if held.likelihood_per_pose_covariance is not None
            else held.per_pose_covariance
        )
    ) / max(float(np.trace(system.shape)), np.finfo(float).tiny)
    local_variance = 0.0 if held.shape_weights is None else 2.0 * float(np.asarray(held.shape_weights) @ SHAPE_TAU) / d

    def scaled(c: float, ell: float) -> tuple[Array, Array]:
        unit = system.unit_covariance(c, ell)
        scale = _leave_one_out_scale(r, fit, n_cov, unit, d, bounds)
        factors = _leave_one_out_components(r, fit, n_cov, unit, d, held_scale if scale is None else scale)
        dof = _leave_one_out_dof(r, fit, n_cov, unit, d, factors, local_variance=local_variance)[0]
        return system.shape * np.outer(factors, factors), np.asarray(dof, dtype=np.float64)

    per_pose, scale_dof = scaled(float(held.correlated_fraction), float(held.length_scale))
    hypotheses = None
    if held.hypotheses is not None:
        hypotheses = tuple(
            FieldHypothesis(
                h.weight, h.correlated_fraction, h.length_scale, *scaled(h.correlated_fraction, h.length_scale)
            )
            for h in held.hypotheses
        )
    return dataclasses.replace(
        held, per_pose_covariance=per_pose, scale_dof=scale_dof, hypotheses=hypotheses, poses_used=int(system.poses)
    )


def _scale_correlation(white: Array) -> float:
    """Correlation of the components' scale estimates: the mean correlation between components
    of the squared whitened leave-one-out prediction errors `white` (n, d), clipped to [0, 0.95].

    The per-component scales are estimated from the same poses. Where the model error is larger
    in some regions of the workspace than in others, in all components together, a campaign
    that happened to sample the quieter (or the louder) regions misjudges every component's
    scale the same way: the estimates are correlated, and a joint statement (the JCGM 102
    region of several components) drawn with independent scale factors averages that common
    error away and is too narrow. Errors whitened by their covariance have uncorrelated
    components, so a correlation of their squares is the common local scale (zero for normal
    errors of one covariance everywhere).
    """
    w2 = np.asarray(white, dtype=np.float64) ** 2
    n, d = w2.shape
    if d < 2 or n < 3:
        return 0.0
    sd = w2.std(axis=0)
    if not np.all(sd > 0.0):
        return 0.0
    corr = np.corrcoef(w2.T)
    mean_off = float((np.sum(corr) - d) / (d * (d - 1)))
    return float(np.clip(mean_off, 0.0, 0.95))


@dataclass(frozen=True, eq=False)
class _ScaleProfile:
    """``f(a) = (sum log(1 + s lambda) + sum u^2 / (1 + s lambda)) / 2`` (``s = e^a``, ``lambda``
    and ``u = W^T y`` from ``M = W diag(lambda) W^T``) without the eigenvectors ``W``.

    A reflection ``H`` takes ``y`` to ``|y| e_1``; LAPACK's tridiagonal reduction of ``H M H``
    (lower form) keeps ``e_1`` fixed, so with ``T`` its tridiagonal matrix ``sum u^2 g(lambda) =
    |y|^2 [g(T)]_11``: ``f`` and its second derivative in ``a`` cost a tridiagonal solve or two
    and a sum over the eigenvalues (``T``'s, no vectors), ``O(m)`` per value of ``s``, after one
    reduction (the reduction is the first part, and a third of the cost, of a full symmetric
    eigendecomposition)."""

    lam: Array
    diag: Array
    off: Array
    norm2: float

    @classmethod
    def of(cls, matrix: Array, y: Array) -> _ScaleProfile:
        from scipy.linalg import eigvalsh_tridiagonal, lapack

        norm = float(np.linalg.norm(y))
        sym = matrix
        if norm > 0.0:
            v = np.array(y, dtype=np.float64)
            v[0] += np.copysign(norm, v[0])
            v /= np.linalg.norm(v)
            w = matrix @ v
            # H M H with H = I - 2 v v^T.
            sym = matrix - 2.0 * np.outer(v, w) - 2.0 * np.outer(w, v) + 4.0 * float(v @ w) * np.outer(v, v)
        _, diag, off, _, info = lapack.dsytrd(sym, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError("tridiagonal reduction failed")
        lam = np.clip(eigvalsh_tridiagonal(diag, off), 0.0, None)
        return cls(np.asarray(lam, dtype=np.float64), np.asarray(diag), np.asarray(off), norm * norm)

    def _solve(self, s: float, rhs: Array) -> Array:
        """``(I + s T)^-1 rhs`` (symmetric positive definite tridiagonal)."""
        from scipy.linalg import solveh_banded

        band = np.empty((2, self.diag.size))
        band[0, 0] = 0.0
        band[0, 1:] = s * self.off
        band[1] = 1.0 + s * self.diag
        return np.asarray(solveh_banded(band, rhs, check_finite=False), dtype=np.float64)

    def half_nll(self, a: float) -> float:
        s = float(np.exp(a))
        first = np.zeros(self.diag.size)
        first[0] = 1.0
        quad = self.norm2 * float(self._solve(s, first)[0])
        return 0.5 * float(np.sum(np.log(1.0 + s * self.lam)) + quad)

    def curvature(self, a: float) -> float:
        """``f''(a)``: ``(sum t (1 - t) + sum u^2 h t (2 t - 1)) / 2`` with ``h = 1 / (1 + s lambda)``,
        ``t = 1 - h``; the second sum is ``y^T (h - 3 h^2 + 2 h^3) y`` from two solves."""
        s = float(np.exp(a))
        t = s * self.lam / (1.0 + s * self.lam)
        first = np.zeros(self.diag.size)
        first[0] = np.sqrt(self.norm2)
        v1 = self._solve(s, first)
        v2 = self._solve(s, v1)
        quad = float(first @ v1) - 3.0 * float(v1 @ v1) + 2.0 * float(v1 @ v2)
        return 0.5 * float(np.sum(t * (1.0 - t)) + quad)


def _hyper_grid_posterior(system: _FieldSystem, log_s: float) -> tuple[list[tuple[float, float]], Array, Array]:
    """The grid ``(c, l)`` of :func:`_hyper_posterior`, its posterior probabilities (the restricted
    likelihood with ``log s`` integrated out by Laplace's method, uniform priors in ``c`` and
    ``log l``; zeros where the likelihood fails everywhere) and each point's profile ``log s``."""
    from scipy import linalg, optimize

    # In the contrasts Q^T r (Q an orthonormal basis orthogonal to the fit) the restricted
    # likelihood is that of N(0, A + s B_cl), A = Q^T N Q, B_cl = Q^T K_cl Q. With A = L L^T and
    # L^-1 B_cl L^-T = W diag(lambda) W^T: 2 nll = log|A| + sum log(1 + s lambda) + sum u^2 / (1 +
    # s lambda), u = W^T L^-1 Q^T r; one tridiagonal reduction per (c, l), any s at O(m)
    # (:class:`_ScaleProfile`).
    del log_s  # the profile maximum is found per point on the eigenvalues
    fit, r = system.fit, system.residuals
    basis = np.linalg.qr(fit, mode="complete")[0][:, fit.shape[1] :]
    chol = linalg.cholesky(basis.T @ system.noise @ basis, lower=True)
    g_mat = linalg.solve_triangular(chol, basis.T, lower=True)  # L^-1 Q^T, (m, n d)
    y = g_mat @ r
    # Ordered by the length first: the systematic resampling stratifies along it.
    grid = [(float(c), float(ell)) for ell in HYPER_LENGTHS for c in HYPER_FRACTIONS]
    log_post = np.empty(len(grid))
    log_scales = np.empty(len(grid))
    # The contrast matrix is linear in c: (1 - c) G (I (x) S) G^T + c G (R_l (x) S) G^T, so one
    # product per length (not per grid point); the same matrices to rounding.
    independent = g_mat @ system.unit_covariance(0.0, 1.0) @ g_mat.T
    correlated: dict[float, Array] = {}
    for g, (c, ell) in enumerate(grid):
        if ell not in correlated:
            correlated[ell] = g_mat @ (system.unit_covariance(1.0, ell)) @ g_mat.T
        profile = _ScaleProfile.of((1.0 - c) * independent + c * correlated[ell], y)
        hi = float(np.log(1e8 / max(float(profile.lam.max()), 1e-300)))
        res = optimize.minimize_scalar(
            profile.half_nll, bounds=(hi - 30.0, hi), method="bounded", options={"xatol": 1e-3}
        )
        a0 = float(res.x)
        curvature = profile.curvature(a0)
        log_scales[g] = a0
        ok = bool(np.isfinite(res.fun) and np.isfinite(curvature))
        log_post[g] = -float(res.fun) - 0.5 * np.log(max(curvature, 1e-12)) if ok else -np.inf
    if not np.any(np.isfinite(log_post)):
        return grid, np.zeros(len(grid)), log_scales
    post = np.exp(log_post - np.max(log_post))
    return grid, np.asarray(post / np.sum(post), dtype=np.float64), log_scales


def _hyper_posterior(system: _FieldSystem, log_s: float, seed: int) -> list[tuple[float, float, float, float]]:
    """Hypotheses ``(weight, c, l, log s)`` representing the posterior of the field's correlation.

    The restricted likelihood of a few tens of poses determines the correlation length and the
    correlated fraction poorly (at 53 UR10 poses the curvature's standard deviation of ``log l``
    is often beyond 1, the maximum at a bound of the range), and a statement that plugs in the
    maximum is too narrow where they matter: how much of the field the fit absorbed at its poses,
    and how much is left at a test configuration near or far from them. They are therefore drawn,
    like the scale and the shape's variation: the restricted likelihood (``s`` integrated out by
    Laplace's method about its profile maximum) on the grid :data:`HYPER_FRACTIONS` x
    :data:`HYPER_LENGTHS` (uniform priors in ``c`` and ``log l``), resampled systematically
    (seeded) to at most :data:`HYPER_DRAWS` hypotheses with their weights.
    """
    grid, post, log_scales = _hyper_grid_posterior(system, log_s)
    if not np.any(post > 0.0):
        return []
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x4C43]))
    positions = (rng.uniform() + np.arange(HYPER_DRAWS)) / HYPER_DRAWS
    picked = np.minimum(np.searchsorted(np.cumsum(post), positions), len(grid) - 1)
    chosen, counts = np.unique(picked, return_counts=True)
    return [
        (float(k) / HYPER_DRAWS, grid[g][0], grid[g][1], float(log_scales[g]))
        for g, k in zip(chosen.tolist(), counts.tolist())
    ]


@dataclass(frozen=True, eq=False)
class _FieldSystem:
    """The whitened residual equations the field's restricted likelihood is made of.

    ``residuals`` (``W r``, length ``n d``), ``fit`` (an orthonormal basis of the whitened
    Jacobian's columns), ``noise`` (``W N W``), ``white`` and ``kron_ones`` (``I (x) S`` and
    ``1 1^T (x) S``, whitened), ``distance`` (chordal, ``n x n``) and ``shape`` (``S`` with
    whitened trace ``d``).
    """

    residuals: Array
    fit: Array
    noise: Array
    white: Array
    kron_ones: Array
    distance: Array
    shape: Array
    dimension: int

    @property
    def poses(self) -> int:
        return int(self.distance.shape[0])

    def unit_covariance(self, c: float, length: float) -> Array:
        """``[c rho(d / l) + (1 - c) I] (x) S``, whitened: the field's covariance per unit scale."""
        d = self.dimension
        unit: Array = np.asarray((1.0 - c) * self.white, dtype=np.float64)
        if c > 0.0:
            rho = kernel_correlation(self.distance, length)
            unit = np.asarray(unit + c * np.repeat(np.repeat(rho, d, axis=0), d, axis=1) * self.kron_ones)
        return np.asarray(unit, dtype=np.float64)

    def nll(self, log_s: float, c: float, log_l: float) -> float:
        """Negative restricted log-likelihood (without its constant) at ``(log s, c, log l)``."""
        from scipy import linalg

        # log|Q^T V Q| = log|V| + log|U^T V^-1 U| and
        # r^T Q (Q^T V Q)^-1 Q^T r = r^T (V^-1 - V^-1 U (U^T V^-1 U)^-1 U^T V^-1) r.
        d, fit, r = self.dimension, self.fit, self.residuals
        s = float(np.exp(log_s))
        # In place, the operations (and roundings) of noise + s (1 - c) white + s c R (x) 1 1^T S.
        cov = self.white * (s * (1.0 - c))
        cov += self.noise
        if c > 0.0:
            rho = kernel_correlation(self.distance, float(np.exp(log_l)))
            correlated = np.repeat(np.repeat(rho, d, axis=0), d, axis=1)
            correlated *= s * c
            correlated *= self.kron_ones
            cov += correlated
        try:
            chol = linalg.cholesky(cov, lower=True, overwrite_a=True)
            vi_u = linalg.cho_solve((chol, True), fit, check_finite=False)
            vi_r = linalg.cho_solve((chol, True), r, check_finite=False)
            chol_u = linalg.cholesky(fit.T @ vi_u, lower=True)
        except (linalg.LinAlgError, ValueError):
            return float("inf")
        z = linalg.solve_triangular(chol_u, fit.T @ vi_r, lower=True)
        quad = float(r @ vi_r - z @ z)
        return float(np.sum(np.log(np.diag(chol))) + np.sum(np.log(np.diag(chol_u))) + 0.5 * quad)


def _field_system(
    calibration: IdentificationResult,
    joint_positions: Array,
    noise: Array,
    shape: Array,
    *,
    max_equations: int,
    seed: int,
) -> _FieldSystem:
    """The whitened residual equations of :func:`estimate_field` (a seeded subset of the poses
    of a campaign with more than `max_equations` equations)."""
    from scipy import linalg

    measurement = calibration.measurement
    residuals = np.asarray(calibration.residuals, dtype=np.float64)
    n_all, d = residuals.shape
    idx = np.arange(n_all)
    max_poses = max(int(max_equations) // d, 1)
    if n_all > max_poses:
        idx = np.sort(np.random.default_rng(seed).choice(n_all, size=max_poses, replace=False))
    q = np.asarray(joint_positions, dtype=np.float64)[idx]
    n = q.shape[0]
    layout = calibration.model.layout
    est = np.flatnonzero(calibration.estimated)
    _, jac = measurement.predict_and_jacobian(layout, calibration.estimate, q)
    w_row = row_weights(measurement, n)
    w = np.ones(n * d) if w_row is None else np.asarray(w_row, dtype=np.float64)
    a_mat = jac.reshape(n * d, layout.size)[:, est] / calibration.column_scale[est] * w[:, None]
    u, sv, _ = np.linalg.svd(a_mat, full_matrices=False)
    fit = u[:, : int(np.sum(sv > 1e-10 * sv[0]))]
    r = residuals[idx].reshape(-1) * w
    w_pose = w[:d]
    shape = np.asarray(shape, dtype=np.float64)
    scale = float(np.trace(w_pose[:, None] * shape * w_pose[None, :])) / d
    if not np.isfinite(scale) or scale <= 0.0:
        shape, scale = np.diag(1.0 / w_pose**2), 1.0
    shape = shape / scale  # whitened trace d
    ww = np.outer(w, w)
    return _FieldSystem(
        residuals=r,
        fit=fit,
        noise=linalg.block_diag(*noise[idx]) * ww,
        white=np.asarray(np.kron(np.eye(n), shape) * ww, dtype=np.float64),
        kron_ones=np.asarray(np.kron(np.ones((n, n)), shape) * ww, dtype=np.float64),
        distance=chordal_distance(q, q),
        shape=shape,
        dimension=d,
    )


def _scale_start_and_bounds(system: _FieldSystem) -> tuple[float, float, float]:
    """The restricted likelihood's starting scale and the bounds of ``log s`` it searches."""
    r = system.residuals
    m = r.size - system.fit.shape[1]
    noise_level = float(np.trace(system.noise)) / r.size
    mean_square = float(r @ r) / max(m, 1)
    s0 = max(mean_square - noise_level, 1e-3 * max(noise_level, 1e-30))
    floor = max(noise_level, 1e-30)
    return s0, float(np.log(1e-6 * floor)), float(np.log(1e4 * max(mean_square, floor)))


def _reml_optimum(system: _FieldSystem) -> tuple[float, float, float, float, float, tuple[float, float]]:
    """Maximum of the restricted likelihood: ``(nll, log s, c, log l)``, the best ``c = 0`` model's
    ``nll``, and the bounds of ``log s`` searched."""
    from scipy import optimize

    nll = system.nll
    s0, lo_s, hi_s = _scale_start_and_bounds(system)
    lo_l, hi_l = np.log(FIELD_LENGTH_BOUNDS[0]), np.log(FIELD_LENGTH_BOUNDS[1])
    independent = optimize.minimize_scalar(lambda a: nll(a, 0.0, 0.0), bounds=(lo_s, hi_s), method="bounded")
    best = (float(independent.fun), float(independent.x), 0.0, float(np.log(0.5)))
    for length in (0.1, 0.5, 2.0):
        res = optimize.minimize(
            lambda t: nll(t[0], t[1], t[2]),
            x0=np.array([np.clip(np.log(s0), lo_s, hi_s), 0.5, np.log(length)]),
            method="L-BFGS-B",
            bounds=[(lo_s, hi_s), (0.0, 1.0), (lo_l, hi_l)],
        )
        if res.fun < best[0]:
            best = (float(res.fun), float(res.x[0]), float(res.x[1]), float(res.x[2]))
    return best[0], best[1], best[2], best[3], float(independent.fun), (float(lo_s), float(hi_s))


def _hyper_covariance(system: _FieldSystem, log_s: float, c: float, log_l: float) -> tuple[Array, float]:
    """Covariance of ``(log s, c, log l)`` (the restricted likelihood's inverse curvature; zero rows
    for those at a bound) and the scale's effective degrees of freedom ``2 / var(log s)``."""
    m = system.residuals.size - system.fit.shape[1]
    free = [0] if c <= 1e-6 else ([0, 1, 2] if c < 1.0 - 1e-6 else [0, 2])
    hess = central_hessian(
        lambda x: system.nll(x[0], min(max(x[1], 0.0), 1.0), x[2]), np.array([log_s, c, log_l]), free
    )
    hyper = np.zeros((3, 3))
    try:
        inv = np.linalg.inv(hess)
    except np.linalg.LinAlgError:
        inv = np.full_like(hess, np.nan)
    var_log_s = float(inv[0, 0])
    if np.all(np.isfinite(inv)) and np.all(np.linalg.eigvalsh(0.5 * (inv + inv.T)) > 0):
        hyper[np.ix_(free, free)] = 0.5 * (inv + inv.T)
    dof = 2.0 / var_log_s if np.isfinite(var_log_s) and var_log_s > 0 else float(m)
    return hyper, dof


def _leverage_inverse(fit: Array, d: int) -> Array:
    """``(I - H_ii)^+`` per pose, shape (n, d, d): ``H = U U^T`` the hat matrix of the orthonormal
    fit basis `fit` (n d, k), its diagonal blocks from the basis's rows (never ``H`` itself)."""
    rows = fit.reshape(fit.shape[0] // d, d, fit.shape[1])
    lever = np.einsum("pik,pjk->pij", rows, rows)
    return np.asarray(np.linalg.pinv(np.eye(d)[None] - lever), dtype=np.float64)


def _projected(matrix: Array, fit: Array) -> Array:
    """``P X P`` for ``P = I - U U^T`` (`fit` = ``U``, orthonormal, (N, k)) at ``O(N^2 k)``:
    ``X - U (U^T X) - (X U) U^T + U (U^T X U) U^T`` (`matrix` = ``X`` symmetric)."""
    xu = matrix @ fit
    inner = fit @ (fit.T @ xu)
    out = matrix - fit @ xu.T - xu @ fit.T + inner @ fit.T
    return np.asarray(out, dtype=np.float64)


def _projected_blocks(matrix: Array, fit: Array, d: int, factors: Array | None = None) -> Array:
    """The per-pose diagonal blocks of ``P D X D P`` (``P`` as in :func:`_projected`, ``D`` the
    per-component `factors` repeated over the poses, the identity without them), shape (n, d, d),
    at ``O(N^2 k)``: ``X_ii - U_i (X U)_i^T - (X U)_i U_i^T + U_i (U^T X U) U_i^T``."""
    n_eq = matrix.shape[0]
    n = n_eq // d
    idx = np.arange(n)
    if factors is None:
        scaled_fit, tiled = fit, None
    else:
        tiled = np.tile(np.asarray(factors, dtype=np.float64), n)
        scaled_fit = fit * tiled[:, None]
    xu = matrix @ scaled_fit  # (N, k): X D U
    if tiled is not None:
        xu = xu * tiled[:, None]  # D X D U
    blocks = matrix.reshape(n, d, n, d)[idx, :, idx, :]
    if tiled is not None:
        f = np.asarray(factors, dtype=np.float64)
        blocks = blocks * np.outer(f, f)[None]
    rows = fit.reshape(n, d, -1)
    xu_rows = xu.reshape(n, d, -1)
    inner = fit.T @ xu  # U^T D X D U, (k, k)
    cross = np.einsum("pik,pjk->pij", rows, xu_rows)
    out = blocks - cross - np.swapaxes(cross, 1, 2) + np.einsum("pik,kl,pjl->pij", rows, inner, rows)
    return np.asarray(out, dtype=np.float64)


def _leave_one_out_scale(
    r: Array, fit: Array, noise: Array, unit: Array, d: int, bounds: tuple[float, float]
) -> float | None:
    """The field's scale ``s`` at which the leave-one-out prediction errors have the spread the
    field states for them.

    For the (linearised) least-squares fit with hat matrix ``H = U U^T`` the prediction error of
    pose i by a fit without it is ``(I - H_ii)^-1 r_i`` exactly, with covariance
    ``(I - H_ii)^-1 [P V P]_ii (I - H_ii)^-T`` (``P = I - H``, ``V = N + s K``): the statement a
    calibration makes at a configuration it did not see, cross term included. Its standardised
    square is ``r_i^T [P V P]_ii^-1 r_i``; ``s`` makes their mean equal to ``d`` (bisection: the
    mean decreases with ``s``). The restricted likelihood fixes the correlation (``c``, ``l``);
    this estimate of the scale depends only on the per-pose blocks, so a misstated correlation
    (too smooth a field, too much absorbed by the fit) shows as larger prediction errors and a
    larger scale, not as an over-confident statement (cross-validated variance estimation is the
    robust one under a misspecified kernel: Bachoc 2013, Comput. Stat. Data Anal. 66).
    """
    n = r.size // d
    pnp = _projected_blocks(noise, fit, d)
    pkp = _projected_blocks(unit, fit, d)
    # The residual's part in the fit space (a regularised fit leaves some) is no prediction error:
    # the model's residual is P (e + eps), as in the restricted likelihood's contrasts.
    r_pose = (r - fit @ (fit.T @ r)).reshape(n, d)

    def excess(log_s: float) -> float:
        blocks = pnp + float(np.exp(log_s)) * pkp
        sol = np.linalg.solve(blocks + 1e-300 * np.eye(d), r_pose[..., None])[..., 0]
        return float(np.mean(np.sum(r_pose * sol, axis=1))) / d - 1.0

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    if excess(lo) <= 0.0:
        return float(bounds[0])
    if excess(hi) >= 0.0:
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if excess(mid) > 0.0:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))


def _leave_one_out_components(
    r: Array, fit: Array, noise: Array, unit: Array, d: int, scale: float, iterations: int = 40
) -> Array:
    """Per-component factors ``f_j`` of the field (``Sigma_m = diag(f) S diag(f)``) at which every
    component's leave-one-out prediction errors have the spread the field states for them.

    The pooled scale of :func:`_leave_one_out_scale` matches their mean over the components;
    the correlation length is shared by all components, and a component the field states too
    smooth (say the rotations of a 6-DOF pose, or one axis) would keep a too narrow statement.
    Here, with ``e_i = (I - H_ii)^-1 r_i`` and its stated covariance ``M_i`` (as there), every
    component's mean of ``e_ij^2 / M_i,jj`` is brought to 1 by the fixed-point iteration
    ``f_j <- f_j sqrt(mean)``; starting from ``f = sqrt(s)``. Returns ``f``, shape (d,).
    """
    n = r.size // d
    inv = _leverage_inverse(fit, d)
    pnp = _projected_blocks(noise, fit, d)
    err = np.einsum("pij,pj->pi", inv, (r - fit @ (fit.T @ r)).reshape(n, d))
    factors = np.full(d, np.sqrt(max(scale, 0.0)))
    if not np.all(factors > 0.0):
        return factors
    for _ in range(iterations):
        pkp = _projected_blocks(unit, fit, d, factors)
        stated = np.einsum("pij,pjk,plk->pil", inv, pnp + pkp, inv)
        ratio = np.mean(err**2 / np.maximum(np.diagonal(stated, axis1=1, axis2=2), np.finfo(float).tiny), axis=0)
        if np.max(np.abs(ratio - 1.0)) < 1e-3:
            break
        factors = factors * np.sqrt(ratio)
    return np.asarray(factors, dtype=np.float64)


def _leave_one_out_dof(
    r: Array,
    fit: Array,
    noise: Array,
    unit: Array,
    d: int,
    factors: Array,
    *,
    heavy_tails: bool = True,
    local_variance: float = 0.0,
) -> tuple[Array, Array, float]:
    """Effective degrees of freedom of each component's leave-one-out scale, shape (d,); the
    leave-one-out prediction errors whitened by their stated covariance, shape (n, d); and the
    effective number of independent poses they hold (a float).

    Component ``j``'s factor makes the mean of ``z_ij^2`` one (:func:`_leave_one_out_components`),
    ``z_ij = e_ij / sqrt(M_i,jj)`` the standardised leave-one-out prediction errors. Under the
    fitted field ``z = G r`` is normal with covariance ``C = G P V P G^T``, so the mean of the
    ``n`` squares has variance ``2 tr(C_j^2) / n^2`` and (Satterthwaite) ``nu_j = tr(C_j)^2 /
    tr(C_j^2)`` degrees of freedom (``C_j`` the component's ``n x n`` block): far fewer than
    ``n`` when the field correlates the poses' errors, as the scale of a smooth error is seen
    by a few independent patches of the workspace only. Heavier tails than the normal's make
    a mean of squares more variable: ``nu_j`` is multiplied by ``2 / (kappa_j - 1)`` (``kappa_j``
    the kurtosis of the observed ``z_ij``; the normal's 3 leaves it), never raised by it. Where
    the tails come from a local variance ``v`` that varies smoothly over the workspace (on the
    UR10 series the squared errors of nearest neighbours correlate by 0.3-0.4), the excess
    variability of the squares is not independent from pose to pose either: with ``v``
    correlated as the error itself (``C``, clipped at 0) and ``var(v) = kappa_j / 3 - 1``,
    ``nu_j = 2 tr(C_j)^2 / (2 tr(C_j^2) + var(v) sum C_j o (1 + 2 C_j o C_j))``; the smaller of
    the two is taken; `local_variance` is a lower bound on ``var(v)`` (the shape posterior's,
    :func:`estimate_field`). The effective number of poses is the mean of the ``nu_j`` before
    that (a normal field's).
    """
    n = r.size // d
    inv = _leverage_inverse(fit, d)
    tiled = np.tile(np.asarray(factors, dtype=np.float64), n)
    cov_r = _projected(noise + unit * np.outer(tiled, tiled), fit)
    # G: (I - H_ii)^-1 per pose (block diagonal, applied block by block), then every component
    # divided by its stated standard deviation.
    cov_e = np.einsum("iac,icjb->iajb", inv, cov_r.reshape(n, d, n, d), optimize=True)
    cov_e = np.einsum("iajc,jbc->iajb", cov_e, inv, optimize=True).reshape(r.size, r.size)
    e = np.einsum("iab,ib->ia", inv, (r - fit @ (fit.T @ r)).reshape(n, d))
    sd = np.sqrt(np.maximum(np.diag(cov_e), np.finfo(float).tiny))
    cov_z = cov_e / np.outer(sd, sd)
    z = e.reshape(-1) / sd
    out = np.empty(d)
    gaussian = np.empty(d)
    for j in range(d):
        cj = cov_z[j::d, j::d]
        tr2 = float(np.sum(cj * cj))
        gaussian[j] = float(np.trace(cj)) ** 2 / tr2 if tr2 > 0.0 else float(n)
        zj = z[j::d]
        kurtosis = float(np.mean(zj**4)) / max(float(np.mean(zj**2)) ** 2, np.finfo(float).tiny)
        out[j] = gaussian[j]
        if heavy_tails:
            # z = sqrt(v) g: g the normal field, v a local variance (mean 1, variance kappa / 3 - 1)
            # varying over the workspace as the error does (correlation C, clipped at 0):
            # Cov(z_i^2, z_k^2) = 2 C_ik^2 + var(v) C_ik (1 + 2 C_ik^2).
            var_v = max(kurtosis / 3.0 - 1.0, float(local_variance), 0.0)
            spatial = float(np.sum(np.clip(cj, 0.0, 1.0) * (1.0 + 2.0 * cj * cj)))
            mixed = 2.0 * float(np.trace(cj)) ** 2 / max(2.0 * tr2 + var_v * spatial, np.finfo(float).tiny)
            independent = gaussian[j] * min(1.0, 2.0 / max(kurtosis - 1.0, np.finfo(float).tiny))
            out[j] = min(independent, mixed)
    idx = np.arange(n)
    evals, evecs = np.linalg.eigh(cov_e.reshape(n, d, n, d)[idx, :, idx, :])
    floor = np.finfo(float).tiny * np.maximum(evals[:, -1:], 1.0)
    root_inv = evecs / np.sqrt(np.maximum(evals, floor))[:, None, :]
    white = np.einsum("pji,pj->pi", root_inv, e)
    return np.asarray(out, dtype=np.float64), white, float(min(float(np.mean(gaussian)), n))


def _wishart_factors(tau: float, d: int, uniforms: Array, normals: Array) -> Array:
    """Bartlett factors ``B`` (lower triangular, shape (m, d, d)) of ``W = B B^T ~ Wishart(I / k, k)``,
    ``k = d / tau``, from given uniforms (m, d) and normals (m, d, d): common random numbers over ``tau``."""
    from scipy import stats

    k = d / tau
    m = uniforms.shape[0]
    factor = np.tril(normals, -1)
    diag = np.sqrt(2.0 * stats.gamma.ppf(uniforms, (k - np.arange(d)) / 2.0))
    factor[:, np.arange(d), np.arange(d)] = diag
    return np.asarray(factor / np.sqrt(k), dtype=np.float64).reshape(m, d, d)


def _whiten_by_the_others(white: Array) -> Array:
    """Every row of `white` (n, d) whitened by the mean outer product of the other rows, shape (n, d).

    The leave-one-out prediction errors are whitened by a covariance estimated from the same
    poses, each one included: an error far out in one direction has widened that covariance and
    looks less extreme than the error of a configuration the calibration did not see would (at
    53 poses, enough to hide much of the workspace variation of the shape). The covariance of the
    others, ``S_-i = (n S - w_i w_i^T) / (n - 1)`` with ``S`` the mean outer product, takes it out.
    """
    w = np.asarray(white, dtype=np.float64)
    n, d = w.shape
    if n <= d + 1:
        return w
    total = w.T @ w
    others = (total[None] - np.einsum("ni,nj->nij", w, w)) / (n - 1)
    evals, evecs = np.linalg.eigh(others)
    evals = np.maximum(evals, 1e-12 * np.max(evals, axis=1, keepdims=True))
    coords = np.einsum("nji,nj->ni", evecs, w) / np.sqrt(evals)
    return np.asarray(np.einsum("nij,nj->ni", evecs, coords), dtype=np.float64)


def _shape_posterior(white: Array, n_eff: float, seed: int) -> Array:
    """Posterior probabilities over :data:`SHAPE_TAU` of how much the per-pose covariance varies
    over the workspace, from the whitened leave-one-out prediction errors `white` (n, d).

    A real model error is not equally large, nor equally shaped, everywhere: at 632 poses of the
    UR10 series D the residuals whitened by one global covariance have 1.31 times a normal's
    multivariate kurtosis, whitened by their 60 nearest neighbours' covariance 1.05 (local
    correlations between the axes from -0.5 to 0.5, local standard deviations varying 2-3 fold).
    With one covariance for the whole workspace a statement at one configuration is right on
    average per axis but too narrow jointly (the JCGM 102 region). The model: the error at a
    configuration is normal with a local covariance ``Sigma_m^(1/2) W Sigma_m^(1/2)``, ``W``
    Wishart with mean ``I`` and ``k = d / tau`` degrees of freedom (``tau = 0``: ``W = I``); a
    variance mixture of normals, multivariate kurtosis ``d (d + 2) (1 + 2 / k)``.

    ``tau`` is a hyperparameter that 53 poses determine poorly (a sample kurtosis of heavy-tailed
    errors is biased low), so it is not plugged in: its posterior (uniform prior on the grid,
    the mixture's density a Monte Carlo integral over :data:`SHAPE_DRAWS` seeded Wishart draws,
    the log-likelihood weighted by `n_eff` / n for the correlation between the poses' errors)
    is drawn from, a draw at a time. Each error is first whitened by the covariance of the others
    (:func:`_whiten_by_the_others`): the scale and the shape are estimated from the same poses, and a
    configuration the calibration did not see is not among them.
    """
    from scipy.special import logsumexp

    w = np.asarray(white, dtype=np.float64)
    n, d = w.shape
    w = _whiten_by_the_others(w)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5A4E]))
    uniforms = rng.uniform(size=(SHAPE_DRAWS, d))
    normals = rng.standard_normal((SHAPE_DRAWS, d, d))
    log_like = np.empty(SHAPE_TAU.size)
    log_norm = -0.5 * d * np.log(2.0 * np.pi)
    log_like[0] = float(np.sum(log_norm - 0.5 * np.sum(w * w, axis=1)))
    for m, tau in enumerate(SHAPE_TAU[1:], start=1):
        factor = _wishart_factors(float(tau), d, uniforms, normals)
        y = w[None] @ np.swapaxes(np.linalg.inv(factor), 1, 2)  # (draws, n, d)
        log_det = np.sum(np.log(np.abs(np.diagonal(factor, axis1=1, axis2=2))), axis=1)
        dens = (log_norm - log_det)[:, None] - 0.5 * np.einsum("snd,snd->sn", y, y)
        log_like[m] = float(np.sum(logsumexp(dens, axis=0) - np.log(SHAPE_DRAWS)))
    log_post = log_like * (min(float(n_eff), n) / n)
    post = np.exp(log_post - np.max(log_post))
    return np.asarray(post / np.sum(post), dtype=np.float64)


def standardised_innovations(residuals: Array) -> Array | None:
    """The residuals centred and whitened to identity covariance, shape (n, d); None when their
    covariance is singular (a direction without scatter: normal innovations then).

    Resampling them keeps the shape of the residual distribution (its tails, its mixture of
    directions) in the drawn model errors, at exactly the field's covariance.
    """
    r = np.asarray(residuals, dtype=np.float64)
    if r.shape[0] < 2 * r.shape[1]:
        return None
    centred = r - r.mean(axis=0)
    evals, evecs = np.linalg.eigh(centred.T @ centred / r.shape[0])
    if evals[0] <= 1e-12 * max(float(evals[-1]), np.finfo(float).tiny):
        return None
    return np.asarray(centred @ (evecs / np.sqrt(evals)) @ evecs.T, dtype=np.float64)


def _scale_moments(dof: Array, rho: float = 0.0) -> Array:
    """``M_jk = E[g_j g_k]`` of independent ``g_j = sqrt(nu_j / chi2(nu_j))``, shape (d, d):
    ``nu_j / (nu_j - 2)`` on the diagonal, ``E[g_j] E[g_k]`` off it (``E[g] = sqrt(nu / 2)
    Gamma((nu - 1) / 2) / Gamma(nu / 2)``, plus ``rho`` times the product of their standard
    deviations where they are correlated); 1 where ``nu`` is infinite."""
    from scipy.special import gammaln

    nu = np.asarray(dof, dtype=np.float64)
    finite = nu < _T_DOF_MAX
    nu = np.where(finite, nu, 3.0)
    mean = np.where(finite, np.sqrt(nu / 2.0) * np.exp(gammaln((nu - 1.0) / 2.0) - gammaln(nu / 2.0)), 1.0)
    second = np.where(finite, nu / (nu - 2.0), 1.0)
    # Correlated factors (a Gaussian copula of correlation rho): Pearson's correlation of such
    # near-normal factors is rho to first order.
    sd = np.sqrt(np.clip(second - mean**2, 0.0, None))
    moments = np.outer(mean, mean) + float(rho) * np.outer(sd, sd)
    np.fill_diagonal(moments, second)
    return np.asarray(moments, dtype=np.float64)


def _is_lower(matrix: Array) -> bool:
    """Whether `matrix` (square) is lower triangular (a Cholesky factor, not an eigen-factor)."""
    return not bool(np.any(np.triu(matrix, 1)))


def _psd_factor(matrix: Array) -> Array:
    """A factor ``F`` with ``F F^T = matrix`` (Cholesky; symmetric eigen-factor when singular)."""
    sym = 0.5 * (matrix + matrix.T)
    try:
        return np.asarray(np.linalg.cholesky(sym), dtype=np.float64)
    except np.linalg.LinAlgError:
        evals, evecs = np.linalg.eigh(sym)
        return np.asarray(evecs * np.sqrt(np.clip(evals, 0.0, None)), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class _Correlation:
    """The factors of one hypothesis's draw (see :class:`FieldNormal`): ``L`` (``C_tt = L L^T``),
    ``B = c R_ct L^-T``, the conditional factor of the test configurations (a matrix, or its
    diagonal beyond :data:`JOINT_TEST_MAX`), ``Sigma_m^(1/2)``, the scale's degrees of freedom
    (None: known) and the GUM's factor of ``M o Sigma_m``."""

    tt: Array
    ct: Array
    cc: Array
    root: Array
    dof: Array | None
    gum_root: Array

    @classmethod
    def build(
        cls, qt: Array, qc: Array, c: float, ell: float, sigma: Array, scale_dof: Array | None, rho: float = 0.0
    ) -> _Correlation:
        n_t = qt.shape[0]
        c_tt = c * kernel_correlation(chordal_distance(qt, qt), ell) + (1.0 - c) * np.eye(n_t)
        l_tt = _psd_factor(c_tt + _JITTER * np.eye(n_t))
        r_ct = c * kernel_correlation(chordal_distance(qc, qt), ell)
        # B = c R_ct L^-T: Cov(B z_t, L z_t) = c R_ct. A Cholesky factor well away from singular
        # (every grid hypothesis: c <= 0.9) by substitution, the same solution as least squares.
        diag = np.abs(np.diag(l_tt))
        if _is_lower(l_tt) and float(diag.min()) > 1e-6 * float(diag.max()):
            from scipy.linalg import solve_triangular

            b = solve_triangular(l_tt, r_ct.T, lower=True, check_finite=False).T
        else:
            b = np.linalg.lstsq(l_tt, r_ct.T, rcond=None)[0].T
        if qc.shape[0] <= JOINT_TEST_MAX:
            c_cc = c * kernel_correlation(chordal_distance(qc, qc), ell) + (1.0 - c) * np.eye(qc.shape[0])
            cc = _psd_factor(c_cc - b @ b.T + _JITTER * np.eye(qc.shape[0]))
        else:
            cc = np.sqrt(np.clip(1.0 - np.sum(b * b, axis=1), 0.0, None))
        sigma = np.asarray(sigma, dtype=np.float64)
        root = _psd_factor(sigma)
        dof = None if scale_dof is None else np.asarray(scale_dof, dtype=np.float64)
        if dof is not None and (dof.shape != (root.shape[0],) or bool(np.all(dof >= _T_DOF_MAX))):
            dof = None
        if dof is not None:
            # A scale with fewer than MIN_SCALE_DOF degrees of freedom has no finite fourth moment
            # (the estimate as a whole is then not drawn; a hypothesis of it is drawn at the floor).
            dof = np.maximum(dof, MIN_SCALE_DOF)
        gum_root = root if dof is None else _psd_factor(_scale_moments(dof, rho) * sigma)
        return cls(l_tt, np.asarray(b, dtype=np.float64), cc, root, dof, gum_root)

    def scalar_covariance(self) -> Array:
        l_tt, b = self.tt, self.ct
        cc = self.cc @ self.cc.T if self.cc.ndim == 2 else np.diag(self.cc**2)
        top = np.hstack((l_tt @ l_tt.T, -(b @ l_tt.T).T))
        bottom = np.hstack((-(b @ l_tt.T), b @ b.T + cc))
        return np.asarray(np.vstack((top, bottom)), dtype=np.float64)

    def instances(self, z: Array) -> tuple[Array, Array]:
        """``F_s`` applied to standard vectors `z` (n, n_t + n_c, d): ``L z_t`` and ``-(B z_t + L_cc
        z_c)``, component-major (shapes (n, d, n_t) and (n, d, n_c): the configurations along the
        last axis, where the per-draw d x d factors of :meth:`FieldNormal.sample` act on the
        middle one).

        ``L`` is lower triangular (a Cholesky factor): its product is a triangular one (half the
        operations of a general product; the same sums in another order, equal to rounding)."""
        n, n_all, d = z.shape
        n_t = self.tt.shape[0]
        head = np.ascontiguousarray(np.swapaxes(z[:, :n_t], 1, 2)).reshape(n * d, n_t)
        e_c = head @ self.ct.T
        if n_all > n_t:
            tail = np.swapaxes(z[:, n_t:], 1, 2).reshape(n * d, n_all - n_t)
            e_c += tail @ self.cc.T if self.cc.ndim == 2 else tail * self.cc[None, :]
        np.negative(e_c, out=e_c)
        if _is_lower(self.tt):
            from scipy.linalg import blas

            # (L Z^T)^T = Z L^T, Z^T Fortran-ordered as `head` is C-ordered (overwritten in place).
            e_t = blas.dtrmm(1.0, self.tt, head.T, side=0, lower=1, overwrite_b=1).T
        else:
            e_t = head @ self.tt.T
        return e_t.reshape(n, d, n_t), e_c.reshape(n, d, n_all - n_t)

    def whitened(self, sensitivities: Array, n_inst: int, d: int) -> Array:
        n_out = sensitivities.shape[0]
        per_component = sensitivities.reshape(n_out, n_inst, d) @ self.gum_root  # (o, N, d)
        n_t = self.tt.shape[0]
        head, tail = per_component[:, :n_t], per_component[:, n_t:]
        # (S F)_t = S_t L_tt - S_c B, (S F)_c = -S_c L_cc.
        out_t = np.einsum("ote,ts->ose", head, self.tt, optimize=True) - np.einsum(
            "oce,ct->ote", tail, self.ct, optimize=True
        )
        if self.cc.ndim == 2:
            out_c = -np.einsum("oce,cs->ose", tail, self.cc, optimize=True)
        else:
            out_c = -tail * self.cc[None, :, None]
        return np.asarray(np.concatenate((out_t, out_c), axis=1).reshape(n_out, n_inst * d), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class FieldNormal:
    """Joint draw of the field at calibration poses and (negated) at test configurations.

    A :class:`~robocal_uncertainty.montecarlo.distributions.Distribution` of size
    ``(n_t + n_c) d``: pose-major ``e_t`` (the calibration poses' model errors), then
    ``-e_c`` (the test configurations'), see the module docstring. The draws are
    ``(F_s (x) Sigma_m^(1/2)) z``; ``z`` is standard normal, or, with `innovations`, resampled
    from them (the residuals' own distribution, standardised): the covariance is the same either
    way, and with ``c = 0`` the latter is the independent residual bootstrap. With the
    estimate's :attr:`~FieldEstimate.hypotheses` every draw first takes one of them (its
    weight's share of the draws): its correlation ``F_s`` and its ``Sigma_m``, a mixture over
    the posterior of the correlation.

    Parameters
    ----------
    calibration_joints : ndarray, shape (n_t, n_joints) [rad]
    test_joints : ndarray, shape (n_c, n_joints) [rad]
    estimate : FieldEstimate
    innovations : ndarray, shape (m, d), optional
        Zero-mean vectors with identity covariance (:func:`standardised_innovations`).
    """

    calibration_joints: Array
    test_joints: Array
    estimate: FieldEstimate
    innovations: Array | None = None
    _parts: tuple[_Correlation, ...] = field(init=False, repr=False)
    _weights: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        qt = np.asarray(self.calibration_joints, dtype=np.float64)
        qc = np.asarray(self.test_joints, dtype=np.float64)
        if qt.ndim != 2 or qc.ndim != 2 or qt.shape[1] != qc.shape[1]:
            msg = f"field draw: joint arrays of shapes {qt.shape} and {qc.shape} do not match"
            raise ConfigError(msg)
        est = self.estimate
        if est.hypotheses:
            parts = tuple(
                _Correlation.build(
                    qt,
                    qc,
                    float(h.correlated_fraction),
                    float(h.length_scale),
                    h.per_pose_covariance,
                    h.scale_dof,
                    float(est.scale_correlation),
                )
                for h in est.hypotheses
            )
            weights = np.array([float(h.weight) for h in est.hypotheses])
        else:
            parts = (
                _Correlation.build(
                    qt,
                    qc,
                    float(est.correlated_fraction),
                    float(est.length_scale),
                    est.per_pose_covariance,
                    est.scale_dof,
                    float(est.scale_correlation),
                ),
            )
            weights = np.ones(1)
        object.__setattr__(self, "_parts", parts)
        object.__setattr__(self, "_weights", weights / np.sum(weights))

    @property
    def dimension(self) -> int:
        """Components per configuration (d)."""
        return int(self._parts[0].root.shape[0])

    @property
    def size(self) -> int:
        return int(self._parts[0].tt.shape[0] + self._parts[0].ct.shape[0]) * self.dimension

    @property
    def whitened_size(self) -> int:
        """Columns of :meth:`whitened_sensitivities` (one block of :attr:`size` per hypothesis)."""
        return self.size * len(self._parts)

    def mean_vector(self) -> Array:
        return np.zeros(self.size)

    def scalar_covariance(self) -> Array:
        """Correlation (scalar) of ``(e_t, -e_c)`` as drawn, shape (n_t + n_c, n_t + n_c) (over
        the hypotheses, their weighted mean)."""
        return np.asarray(sum(w * p.scalar_covariance() for w, p in zip(self._weights, self._parts)), dtype=np.float64)

    def covariance(self) -> Array:
        """Covariance of the drawn vector, shape (size, size) (the GUM's input covariance):
        ``C_s (x) (M o Sigma_m)``, ``M`` the second moments of the drawn scale factors, summed
        over the hypotheses with their weights."""
        total = np.zeros((self.size, self.size))
        for w, p in zip(self._weights, self._parts):
            total += w * np.kron(p.scalar_covariance(), p.gum_root @ p.gum_root.T)
        return total

    def sample(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` draws, shape (n, size): ``(F_s (x) diag(g) Sigma_m^(1/2) B) z`` with one standard
        normal vector ``z`` per draw and, where the scale is estimated (``nu_j`` finite), per draw
        and component ``g_j = sqrt(nu_j / chi2(nu_j))``: the scale as uncertain as its estimate
        (Student-t marginals, the predictive distribution of a normal quantity whose variance is
        estimated with ``nu_j`` degrees of freedom; JCGM 101 6.4.9). Where the per-pose covariance
        varies over the workspace (:attr:`FieldEstimate.shape_weights` not all on ``tau = 0``),
        per draw ``tau`` from its posterior and ``B`` a Bartlett factor of ``W ~ Wishart(I / k, k)``,
        ``k = d / tau`` (``E[B B^T] = I``: the field's covariance; a local covariance of the draw,
        kept however many calibration poses a test configuration's error is conditioned on,
        where resampled innovations would average out). Otherwise ``z`` is resampled from the
        innovations when given. With several hypotheses of the correlation, each draw first
        takes one (``F_s``, ``Sigma_m`` and ``nu`` are then its). Consumed in a fixed order."""
        n = int(n)
        n_inst, d = self.size // self.dimension, self.dimension
        many = len(self._parts) > 1
        which = rng.choice(len(self._parts), size=n, p=self._weights) if many else np.zeros(n, dtype=np.int64)
        weights = self.estimate.shape_weights
        varying = weights is not None and float(np.asarray(weights)[0]) < 1.0
        if self.innovations is None or varying:
            z = rng.standard_normal((n, n_inst, d))
        else:
            z = self.innovations[rng.integers(0, self.innovations.shape[0], size=(n, n_inst))]
        # Per draw one d x d factor, diag(g) Sigma_m^(1/2) B: the scale factors g, the root of the
        # per-pose covariance and the Wishart factor B of the local covariance (drawn in this order).
        if many:
            mix = np.stack([p.root for p in self._parts])[which]
        else:
            mix = np.broadcast_to(self._parts[0].root, (n, d, d))
        if varying:
            tau = SHAPE_TAU[rng.choice(SHAPE_TAU.size, size=n, p=np.asarray(weights, dtype=np.float64))]
            k_w = d / np.where(tau > 0.0, tau, 1.0)  # tau = 0 (W = I) is replaced below
            factor = np.tril(rng.standard_normal((n, d, d)), -1)
            chi2 = rng.chisquare(k_w[:, None] - np.arange(d))
            factor[:, np.arange(d), np.arange(d)] = np.sqrt(chi2)
            factor = np.where((tau > 0.0)[:, None, None], factor / np.sqrt(k_w)[:, None, None], np.eye(d))
            mix = mix @ factor
        if many:
            dofs = np.stack([np.full(d, _T_DOF_MAX) if p.dof is None else p.dof for p in self._parts])[which]
            if any(p.dof is not None for p in self._parts):
                finite = dofs < _T_DOF_MAX
                dof = np.where(finite, dofs, 3.0)
                mix = mix * np.where(finite, np.sqrt(dof / self._chi2(rng, dof)), 1.0)[:, :, None]
        else:
            part = self._parts[0]
            if part.dof is not None:
                finite = part.dof < _T_DOF_MAX
                dof = np.where(finite, part.dof, 3.0)
                factor_g = np.where(finite, np.sqrt(dof / self._chi2(rng, np.broadcast_to(dof, (n, d)))), 1.0)
                mix = mix * factor_g[:, :, None]
        # The correlation's products run along the configurations (component-major), the d x d
        # factors along the components; written back pose-major.
        out = np.empty((n, n_inst, d))
        if many:
            for k, part in enumerate(self._parts):
                mask = which == k
                e_t, e_c = part.instances(z[mask])
                n_t = e_t.shape[2]
                out[mask, :n_t] = np.swapaxes(mix[mask] @ e_t, 1, 2)
                out[mask, n_t:] = np.swapaxes(mix[mask] @ e_c, 1, 2)
        else:
            e_t, e_c = self._parts[0].instances(z)
            del z
            n_t = e_t.shape[2]
            out[:, :n_t] = np.swapaxes(mix @ e_t, 1, 2)
            out[:, n_t:] = np.swapaxes(mix @ e_c, 1, 2)
        return out.reshape(n, self.size)

    def _chi2(self, rng: np.random.Generator, dof: Array) -> Array:
        """Chi-square variates of degrees of freedom `dof` (n, d), the components of a row
        correlated by :attr:`FieldEstimate.scale_correlation` (a Gaussian copula; independent
        draws where it is zero)."""
        rho = float(self.estimate.scale_correlation)
        if rho <= 0.0:
            return np.asarray(rng.chisquare(dof), dtype=np.float64)
        from scipy import special, stats

        n, d = dof.shape
        u = np.sqrt(1.0 - rho) * rng.standard_normal((n, d)) + np.sqrt(rho) * rng.standard_normal((n, 1))
        prob = np.clip(special.ndtr(u), 1e-15, 1.0 - 1e-15)
        return np.asarray(stats.chi2.ppf(prob, dof), dtype=np.float64)

    def whitened_sensitivities(self, sensitivities: Array) -> Array:
        """``S (F_s (x) Sigma_m^(1/2))``: sensitivities to the standard normal `z` the draws are
        made of, shape (n_out, :attr:`whitened_size`), so their Gram matrix is ``S Cov S^T`` (the
        GUM's propagation without the dense covariance of the draws); with several hypotheses one
        block per hypothesis, scaled by the square root of its weight.

        Parameters
        ----------
        sensitivities : ndarray, shape (n_out, size)
            Derivatives of the outputs by the drawn vector ``(e_t, -e_c)``, pose-major.
        """
        n_inst, d = self.size // self.dimension, self.dimension
        blocks = [np.sqrt(w) * p.whitened(sensitivities, n_inst, d) for w, p in zip(self._weights, self._parts)]
        return blocks[0] if len(blocks) == 1 else np.asarray(np.hstack(blocks), dtype=np.float64)
