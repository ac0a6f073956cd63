"""Bias-corrected intervals of the max/min-defined section parameters.

The reference paper's Monte Carlo perturbs the *measured* cloud. For a parameter that is a maximum or a
minimum over points (maximum thickness, chord, profile deviation = max - min), the measurement
noise already biased the measured value upward, and the Monte Carlo adds the same noise again:
its distribution is centred about ``y + b`` (``b`` the noise bias), not about ``y``. Its
JCGM 101 interval then misses the true value more often than 1 - p.

With the bias taken as the same at the measured and at the true cloud, the Monte Carlo
estimates it as ``b = mean - y`` and the distribution of ``y - truth`` as that of
``sample - y``, so the interval for the truth is the Monte Carlo interval reflected about the
measured value, ``[2y - high, 2y - low]``, and the corrected estimate is ``y - b`` (the
bootstrap "basic" interval, Davison & Hinkley 1997, §5.2). The max/min parameters are
lengths that cannot be negative (a profile deviation is max - min): their corrected estimate
and interval limits are clipped at zero, so a nearly perfect profile (measured value below
the bias) is stated as [0, ...] instead of an interval of negative deviations.

The reflection takes the bias at the measured cloud, where the noise has already pushed the
extreme points out, for the bias at the true cloud; over simulated scans it still under-covers
(thickness 89 %, profiles 7.5-73 %). :func:`~.section_mc.section_uncertainty` with
``method="denoised"`` samples the error around a denoised cloud instead; its Monte Carlo
distribution is already that of the measurand, so for such a result this module only reads
the bias (``f(y)`` minus the Monte Carlo mean), the estimate (the mean) and the interval (the
Monte Carlo interval; for the profiles its union with the intervals at the smoothest and the
roughest form the scan supports, :mod:`.resolution`), clipped at zero for the max/min
parameters. The slow coverage test
measures all of them over simulated scans with a known truth.
"""

from __future__ import annotations

from dataclasses import dataclass

from robocal_uncertainty.inspection.section import PARAMETER_NAMES
from robocal_uncertainty.inspection.section_mc import SectionUncertainty
from robocal_uncertainty.montecarlo.summary import CoverageInterval

__all__ = ["MAX_MIN_PARAMETERS", "BiasCorrection", "bias_corrections"]

_LINEAR = ("axial_offset", "circumferential_offset", "twist_angle")

MAX_MIN_PARAMETERS: tuple[str, ...] = tuple(name for name in PARAMETER_NAMES if name not in _LINEAR)
"""Parameters defined by a maximum or minimum over points: biased by the measurement noise."""


@dataclass(frozen=True)
class BiasCorrection:
    """Bias-corrected statement of one parameter.

    Attributes
    ----------
    name : str
        Parameter name (:data:`~.section.PARAMETER_NAMES`).
    measured : float
        Value of the measured cloud [m or rad].
    bias : float
        Monte Carlo estimate of the noise bias of the measured value [m or rad]: mean - measured
        (method ``perturbed``), measured - mean = mean(Δ) (method ``denoised``).
    estimate : float
        measured - bias [m or rad]; at least 0 for :data:`MAX_MIN_PARAMETERS`.
    interval : CoverageInterval
        Method ``perturbed``: the probabilistically symmetric Monte Carlo interval reflected about
        ``measured`` (kind ``probabilistically_symmetric`` of the reflected distribution);
        method ``denoised``: the probabilistically symmetric Monte Carlo interval itself, for the
        max/min parameters widened to the roughness envelope (:mod:`.resolution`, when the result has one)
        [m or rad]; limits clipped at 0 for :data:`MAX_MIN_PARAMETERS`.
    recommended : bool
        True for :data:`MAX_MIN_PARAMETERS` (state this interval), False for the linear
        parameters (offsets, twist: the JCGM 101 interval is unbiased; this one is shown
        for comparison only).
    """

    name: str
    measured: float
    bias: float
    estimate: float
    interval: CoverageInterval
    recommended: bool


def bias_corrections(result: SectionUncertainty) -> tuple[BiasCorrection, ...]:
    """Bias-corrected estimate and interval of every parameter of `result`.

    Returns
    -------
    tuple of BiasCorrection
        In :data:`~.section.PARAMETER_NAMES` order.
    """
    measured = result.parameters.as_array()
    denoised = result.method == "denoised"
    out = []
    for name, y, output in zip(PARAMETER_NAMES, measured, result.monte_carlo.outputs):
        mc = output.probabilistically_symmetric
        if denoised:  # the Monte Carlo values are f(y) - Δ already
            bias = float(y - output.estimate)
            low, high, estimate = float(mc.low), float(mc.high), float(output.estimate)
            if result.envelope is not None:  # max/min parameters: widened to the roughness limits
                low, high = result.envelope.widen(name, low, high)
        else:
            bias = float(output.estimate - y)
            low, high, estimate = float(2 * y - mc.high), float(2 * y - mc.low), float(y - bias)
        recommended = name in MAX_MIN_PARAMETERS
        if recommended:  # non-negative lengths
            low, high, estimate = max(low, 0.0), max(high, 0.0), max(estimate, 0.0)
        interval = CoverageInterval(low, high, mc.kind, mc.coverage_probability)
        out.append(BiasCorrection(name, float(y), bias, estimate, interval, recommended))
    return tuple(out)
