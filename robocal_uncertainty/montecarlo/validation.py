"""Validation of the GUM uncertainty framework by Monte Carlo (JCGM 101 §8).

The GUM interval [y - U, y + U] is validated when both endpoint differences from the
Monte Carlo probabilistically symmetric interval are within the numerical tolerance
δ of the GUM standard uncertainty (§8.2).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.montecarlo.gum import GumResult
from robocal_uncertainty.montecarlo.summary import OutputSummary, numerical_tolerance

__all__ = ["GumValidation", "validate_gum"]


class MonteCarloOutputs(Protocol):
    """Any Monte Carlo result with per-output summaries: MonteCarloResult or Summary."""

    @property
    def outputs(self) -> Sequence[OutputSummary]: ...

    @property
    def coverage_probability(self) -> float: ...


@dataclass(frozen=True)
class GumValidation:
    """Outcome of JCGM 101 §8.2 for one output component.

    Attributes
    ----------
    output : int
        Output component index.
    d_low : float
        |y - U - y_low|, in the output's unit.
    d_high : float
        |y + U - y_high|, in the output's unit.
    delta : float
        Numerical tolerance δ, in the output's unit.
    n_dig : int or None
        Digits δ came from; None when an absolute tolerance was given.
    validated : bool
        ``d_low <= delta and d_high <= delta``.
    """

    output: int
    d_low: float
    d_high: float
    delta: float
    n_dig: int | None
    validated: bool


def validate_gum(
    gum: GumResult,
    monte_carlo: MonteCarloOutputs,
    *,
    output: int = 0,
    n_dig: int = 2,
    tolerance: float | None = None,
) -> GumValidation:
    """Compare the GUM interval with the Monte Carlo probabilistically symmetric one.

    Parameters
    ----------
    gum : GumResult
        First-order GUM propagation.
    monte_carlo : MonteCarloResult or Summary
        Monte Carlo propagation of the same model, same coverage probability.
    output : int
        Output component to compare.
    n_dig : int
        Significant digits of u_c(y) that define δ (§7.9.2).
    tolerance : float, optional
        Absolute δ in output units, overriding ``n_dig``.

    Returns
    -------
    GumValidation
    """
    n_out = len(gum.outputs)
    if len(monte_carlo.outputs) != n_out:
        msg = f"monte_carlo must have {n_out} outputs like gum, got {len(monte_carlo.outputs)}"
        raise ConfigError(msg)
    if isinstance(output, bool) or not 0 <= output < n_out:
        msg = f"output must be an index in [0, {n_out}), got {output!r}"
        raise ConfigError(msg)
    if not math.isclose(gum.coverage_probability, monte_carlo.coverage_probability):
        msg = (
            f"coverage probabilities differ: gum {gum.coverage_probability}, "
            f"monte_carlo {monte_carlo.coverage_probability}"
        )
        raise ConfigError(msg)
    g = gum.outputs[output]
    mc = monte_carlo.outputs[output].probabilistically_symmetric
    if tolerance is None:
        delta = numerical_tolerance(g.standard_uncertainty, n_dig)
        digits: int | None = int(n_dig)
    else:
        delta = float(tolerance)
        if not (math.isfinite(delta) and delta > 0):
            msg = f"tolerance must be positive and finite, got {tolerance!r}"
            raise ConfigError(msg)
        digits = None
    d_low = abs(g.interval.low - mc.low)
    d_high = abs(g.interval.high - mc.high)
    return GumValidation(output, d_low, d_high, delta, digits, d_low <= delta and d_high <= delta)
