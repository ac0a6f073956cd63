"""GUM law of propagation of uncertainty, first order (JCGM 100 §5, GUM §G.4).

Used as the reference that JCGM 101 §8 validates against Monte Carlo. Sensitivity
coefficients are central differences with step ``h_i = relative_step × u(x_i)``:
scaling the step by each input's own uncertainty makes it commensurate with the
region the model is linearised over, whatever the input's unit (for u(x_i) = 0 the
step is ``relative_step × max(|x_i|, 1)``; the coefficient then carries no weight).
StudentT inputs enter as GUM Type A inputs: standard uncertainty ``scale`` with
``dof`` degrees of freedom, pooled by the Welch-Satterthwaite formula (GUM G.4.1).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats
from scipy.linalg import block_diag

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.distributions import (
    Distribution,
    IndependentCopies,
    IndependentNormal,
    IndependentRectangular,
    StudentT,
)
from robocal_uncertainty.montecarlo.engine import ModelOutputError, resolve_inputs
from robocal_uncertainty.montecarlo.summary import CoverageInterval, check_coverage

__all__ = ["GumOutput", "GumResult", "propagate_gum"]


@dataclass(frozen=True)
class GumOutput:
    """GUM result for one output component.

    Attributes
    ----------
    estimate : float
        y = f(E[X]), in the output's unit.
    standard_uncertainty : float
        Combined standard uncertainty u_c(y), in the output's unit.
    effective_dof : float
        Welch-Satterthwaite ν_eff; ``inf`` when no StudentT input contributes.
    coverage_factor : float
        k from the normal (ν_eff infinite) or Student t distribution.
    expanded_uncertainty : float
        U = k u_c, in the output's unit.
    interval : CoverageInterval
        [y - U, y + U], kind ``"gum"``.
    """

    estimate: float
    standard_uncertainty: float
    effective_dof: float
    coverage_factor: float
    expanded_uncertainty: float
    interval: CoverageInterval


@dataclass(frozen=True, eq=False)
class GumResult:
    """First-order GUM propagation through a (vector) model.

    Attributes
    ----------
    outputs : tuple of GumOutput, length n_out
        Per-output estimate, u_c, ν_eff, k, U and interval.
    covariance : ndarray, shape (n_out, n_out)
        J Σ Jᵀ, in products of the output units.
    sensitivities : ndarray, shape (n_out, n_columns)
        ∂f_j/∂x_i at the input estimates, output unit per input unit.
    input_estimates : ndarray, shape (n_columns,)
        E[X], in the inputs' units.
    input_distributions : tuple of Distribution
        The inputs, in column order (their covariances form Σ).
    input_columns : tuple of str
        Label of each input column.
    coverage_probability : float
        p.
    relative_step : float or None
        Finite-difference step as a fraction of each input's standard uncertainty; None
        when the sensitivities were given analytically.
    """

    outputs: tuple[GumOutput, ...]
    covariance: NDArray[np.float64]
    sensitivities: NDArray[np.float64]
    input_estimates: NDArray[np.float64]
    input_distributions: tuple[Distribution, ...]
    input_columns: tuple[str, ...]
    coverage_probability: float
    relative_step: float | None

    @property
    def input_covariance(self) -> NDArray[np.float64]:
        """Σ, shape (n_columns, n_columns), block diagonal over inputs (built on demand)."""
        return np.asarray(block_diag(*[_input_covariance(d) for d in self.input_distributions]), dtype=np.float64)


def _input_covariance(dist: Distribution) -> NDArray[np.float64]:
    """Covariance of one input as the GUM takes it (Type A scale² for StudentT)."""
    if isinstance(dist, StudentT):
        return np.array([[dist.scale**2]])
    return np.atleast_2d(np.asarray(dist.covariance(), dtype=np.float64))


def _variances(dist: Distribution) -> NDArray[np.float64]:
    """Diagonal of one input's covariance, without building it when the input is independent."""
    if isinstance(dist, (IndependentRectangular, IndependentNormal)):
        return dist.variance_vector()
    if isinstance(dist, IndependentCopies):
        return np.tile(np.diag(np.atleast_2d(dist.block_covariance())), dist.count)
    return np.diag(_input_covariance(dist)).copy()


def _propagated(jacobian: NDArray[np.float64], dist: Distribution) -> NDArray[np.float64]:
    """J_d Σ_d J_dᵀ of one input, exploiting diagonal and block-diagonal Σ_d."""
    if isinstance(dist, (IndependentRectangular, IndependentNormal)):
        return np.asarray((jacobian * dist.variance_vector()) @ jacobian.T, dtype=np.float64)
    if isinstance(dist, IndependentCopies):
        block = np.atleast_2d(dist.block_covariance())
        parts = jacobian.reshape(jacobian.shape[0], dist.count, block.shape[0])
        return np.asarray(np.einsum("ocm,mn,pcn->op", parts, block, parts, optimize=True), dtype=np.float64)
    return np.asarray(jacobian @ _input_covariance(dist) @ jacobian.T, dtype=np.float64)


def _propagated_blocks(jacobian: NDArray[np.float64], dist: Distribution, block: int) -> NDArray[np.float64]:
    """The diagonal blocks of J_d Σ_d J_dᵀ, shape (n_out // block, block, block): outputs in
    consecutive groups of `block` (a configuration's x, y, z), no covariance between groups."""
    rows = jacobian.reshape(jacobian.shape[0] // block, block, jacobian.shape[1])
    if isinstance(dist, (IndependentRectangular, IndependentNormal)):
        return np.asarray(np.matmul(rows * dist.variance_vector(), np.swapaxes(rows, 1, 2)), dtype=np.float64)
    if isinstance(dist, IndependentCopies):
        copy_cov = np.atleast_2d(dist.block_covariance())
        scaled = (rows.reshape(rows.shape[0], block, dist.count, copy_cov.shape[0]) @ copy_cov).reshape(rows.shape)
        return np.asarray(np.matmul(scaled, np.swapaxes(rows, 1, 2)), dtype=np.float64)
    return np.asarray(np.matmul(rows @ _input_covariance(dist), np.swapaxes(rows, 1, 2)), dtype=np.float64)


def _model_values(model: Callable[[NDArray[np.float64]], ArrayLike], x: NDArray[np.float64]) -> NDArray[np.float64]:
    rows = x.shape[0]
    values = np.asarray(model(x), dtype=np.float64)
    if values.ndim == 1 and values.shape[0] == rows:
        values = values[:, np.newaxis]
    if values.ndim != 2 or values.shape[0] != rows or values.shape[1] < 1:
        msg = f"model output must have shape ({rows},) or ({rows}, n_out), got {values.shape}"
        raise ModelOutputError(msg)
    bad = int((~np.isfinite(values)).sum())
    if bad:
        msg = f"model returned {bad} non-finite values at the GUM evaluation points"
        raise ModelOutputError(msg)
    return values


def propagate_gum(
    model: Callable[[NDArray[np.float64]], ArrayLike],
    inputs: Sequence[Distribution] | Mapping[str, Distribution],
    *,
    coverage: float = 0.95,
    relative_step: float = 1e-2,
    sensitivities: ArrayLike | None = None,
    output_blocks: int | None = None,
) -> GumResult:
    """First-order law of propagation of uncertainty for the same model as Monte Carlo.

    Parameters
    ----------
    model : callable
        Vectorised model, x of shape (n, n_columns) -> (n,) or (n, n_out); it is
        called once with 1 + 2 n_columns rows (once with 1 row when `sensitivities`
        are given).
    inputs : sequence of Distribution or mapping of str to Distribution
        Inputs, as for :func:`~robocal_uncertainty.montecarlo.engine.monte_carlo`;
        correlations inside CorrelatedNormal/Empirical vector inputs are propagated.
        Independent vector inputs (IndependentRectangular, IndependentCopies) are
        propagated without forming their dense covariance, so thousands of input
        columns cost little memory.
    coverage : float
        Coverage probability p.
    relative_step : float
        Central-difference step as a fraction of each input's standard uncertainty,
        in (0, 1].
    sensitivities : array_like, shape (n_out, n_columns), optional
        Analytic sensitivity coefficients ∂f_j/∂x_i (output unit per input unit) at the
        input estimates (GUM §5.1.3), e.g. from a linearised model whose finite
        differences would cost thousands of model evaluations.
    output_blocks : int, optional
        Propagate the covariance only within consecutive groups of this many outputs (e.g. the
        x, y, z of each of thousands of configurations): ``covariance`` is then block diagonal,
        zero between groups, and costs n_out x block instead of n_out² products per input
        column. The variances, hence every output, are those of the full propagation (to
        rounding). Default: the full covariance.

    Returns
    -------
    GumResult
    """
    p = check_coverage(coverage)
    step = float(relative_step)
    if not 0.0 < step <= 1.0:
        msg = f"relative_step must lie in (0, 1], got {relative_step!r}"
        raise ConfigError(msg)
    _, distributions, columns = resolve_inputs(inputs)
    x0 = np.concatenate([d.mean_vector() for d in distributions])
    variances = np.concatenate([_variances(d) for d in distributions])
    dof = np.concatenate(
        [np.full(d.size, d.dof if isinstance(d, StudentT) else math.inf, dtype=np.float64) for d in distributions]
    )
    if not np.isfinite(variances).all():
        msg = "every input must have a finite standard uncertainty for the GUM, got inf"
        raise ConfigError(msg)
    u_in = np.sqrt(np.clip(variances, 0.0, None))
    y, jacobian, used_step = _sensitivities(model, x0, u_in, step, sensitivities)
    covariance = _covariance(jacobian, distributions, output_blocks)
    outputs = _outputs(y, covariance, jacobian, u_in, dof, p)
    for array in (covariance, jacobian, x0):
        array.setflags(write=False)
    return GumResult(tuple(outputs), covariance, jacobian, x0, distributions, columns, p, used_step)


def _covariance(
    jacobian: NDArray[np.float64], distributions: Sequence[Distribution], output_blocks: int | None
) -> NDArray[np.float64]:
    """Σ_d J_d Σ_d J_dᵀ over the inputs, symmetrised; only its diagonal blocks with `output_blocks`."""
    n_out = jacobian.shape[0]
    if output_blocks is not None and (output_blocks < 1 or n_out % output_blocks):
        msg = f"output_blocks must divide the {n_out} outputs, got {output_blocks!r}"
        raise ConfigError(msg)
    blocks = None if output_blocks is None else np.zeros((n_out // output_blocks, output_blocks, output_blocks))
    covariance = np.zeros((n_out, n_out))
    start = 0
    for dist in distributions:
        stop = start + dist.size
        if blocks is None:
            covariance += _propagated(jacobian[:, start:stop], dist)
        else:
            blocks += _propagated_blocks(jacobian[:, start:stop], dist, output_blocks or 1)
        start = stop
    if blocks is not None:
        n_groups, size = blocks.shape[:2]
        groups = np.arange(n_groups)
        covariance.reshape(n_groups, size, n_groups, size)[groups, :, groups, :] = blocks
    return 0.5 * (covariance + covariance.T)


def _sensitivities(
    model: Callable[[NDArray[np.float64]], ArrayLike],
    x0: NDArray[np.float64],
    u_in: NDArray[np.float64],
    step: float,
    sensitivities: ArrayLike | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float | None]:
    """The model's value at the estimates x0 and its Jacobian: the given `sensitivities`, or
    central differences of `step` standard uncertainties (`step` times max(|x|, 1) for an
    exact input); returns them and the step used (None for given sensitivities)."""
    n = x0.size
    if sensitivities is None:
        h = np.where(u_in > 0, step * u_in, step * np.maximum(np.abs(x0), 1.0))
        points = np.vstack([x0, x0 + np.diag(h), x0 - np.diag(h)])
        values = _model_values(model, points)
        y = values[0]
        jacobian = ((values[1 : n + 1] - values[n + 1 :]) / (2.0 * h)[:, np.newaxis]).T
        return y, jacobian, step
    y = _model_values(model, x0[np.newaxis, :])[0]
    jacobian = np.array(sensitivities, dtype=np.float64)
    if jacobian.shape != (y.shape[0], n) or not np.isfinite(jacobian).all():
        msg = f"sensitivities must be finite with shape ({y.shape[0]}, {n}), got {jacobian.shape}"
        raise ConfigError(msg)
    return y, jacobian, None


def _outputs(
    y: NDArray[np.float64],
    covariance: NDArray[np.float64],
    jacobian: NDArray[np.float64],
    u_in: NDArray[np.float64],
    dof: NDArray[np.float64],
    p: float,
) -> list[GumOutput]:
    """Every output's estimate, standard uncertainty, Welch-Satterthwaite degrees of freedom,
    coverage factor and interval."""
    u_c = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    student = np.isfinite(dof)
    # The normal factor once: scipy's ppf costs ~0.3 ms a call, thousands of outputs share it.
    k_normal = float(stats.norm.ppf(0.5 * (1 + p)))
    outputs = []
    for j in range(y.shape[0]):
        if student.any():
            contributions = (jacobian[j, student] * u_in[student]) ** 4 / dof[student]
            denominator = float(contributions.sum())
        else:
            denominator = 0.0
        nu = u_c[j] ** 4 / denominator if denominator > 0 else math.inf
        k = k_normal if math.isinf(nu) else float(stats.t.ppf(0.5 * (1 + p), nu))
        expanded = k * float(u_c[j])
        interval = CoverageInterval(float(y[j]) - expanded, float(y[j]) + expanded, "gum", p)
        outputs.append(GumOutput(float(y[j]), float(u_c[j]), nu, k, expanded, interval))
    return outputs
