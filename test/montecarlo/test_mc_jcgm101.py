"""JCGM 101:2008 worked examples (§9.2 additive models, §9.3 mass calibration).

Monte Carlo tolerances are a few standard errors of the quantity at the M used
(se of a 97.5 % quantile: sqrt(p(1-p)/M)/f(y_q); se of u: u sqrt((κ-1)/(4M))) plus
half a unit of the last digit printed in JCGM 101; GUM results are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from robocal_uncertainty.montecarlo import (
    Normal,
    Rectangular,
    monte_carlo,
    propagate_gum,
    validate_gum,
)

SQRT3 = math.sqrt(3.0)


def additive(x: np.ndarray) -> np.ndarray:
    return x.sum(axis=1)


def mass_model(x: np.ndarray) -> np.ndarray:
    """JCGM 101 9.3: δm = (m_R,c + δm_R,c)(1 + (ρ_a - ρ_a0)(1/ρ_W - 1/ρ_R)) - m_nom [mg]."""
    m_rc, dm_rc, rho_a, rho_w, rho_r = x.T
    return (m_rc + dm_rc) * (1.0 + (rho_a - 1.2) * (1.0 / rho_w - 1.0 / rho_r)) - 100_000.0


MASS_INPUTS = {
    "m_Rc": Normal(100_000.000, 0.050),  # mg
    "dm_Rc": Normal(1.234, 0.020),  # mg
    "rho_a": Rectangular(1.10, 1.30),  # kg/m³
    "rho_W": Rectangular(7_000.0, 9_000.0),  # kg/m³
    "rho_R": Rectangular(7_950.0, 8_050.0),  # kg/m³
}


def irwin_hall_quantile(p: float, n: int) -> float:
    """Exact quantile of the sum of n standard uniforms (independent reference)."""

    def cdf(s: float) -> float:
        terms = ((-1) ** k * math.comb(n, k) * (s - k) ** n for k in range(math.floor(s) + 1))
        return sum(terms) / math.factorial(n)

    return float(brentq(lambda s: cdf(s) - p, 0.0, float(n)))


def test_9_2_2_four_normal_inputs() -> None:
    inputs = [Normal(0.0, 1.0)] * 4
    mc = monte_carlo(additive, inputs, seed=922, trials=1_000_000)
    out = mc.outputs[0]
    # se(y) = 2/1000 = 0.002; se(u) = 2 sqrt(2/4e6) = 0.0014; se(quantile) = 0.0054.
    assert abs(out.estimate) <= 0.01
    assert out.standard_uncertainty == pytest.approx(2.0, abs=0.007)
    assert out.probabilistically_symmetric.low == pytest.approx(-3.92, abs=0.005 + 0.022)
    assert out.probabilistically_symmetric.high == pytest.approx(3.92, abs=0.005 + 0.022)
    assert out.coverage_factor == pytest.approx(1.96, abs=0.015)
    gum = propagate_gum(additive, inputs)
    g = gum.outputs[0]
    # GUM is exact for a linear model: u = 2, U = 1.96 × 2 = 3.92 (to round-off).
    assert g.estimate == pytest.approx(0.0, abs=1e-12)
    assert g.standard_uncertainty == pytest.approx(2.0, rel=1e-9)
    assert g.interval.high == pytest.approx(3.919928, rel=1e-6)
    check = validate_gum(gum, mc, n_dig=2)
    assert check.delta == pytest.approx(0.05)  # u = 20 × 10^-1
    assert check.validated and max(check.d_low, check.d_high) <= 0.03


def test_9_2_3_four_rectangular_inputs() -> None:
    inputs = [Rectangular.from_centre(0.0, SQRT3)] * 4  # each u = 1
    mc = monte_carlo(additive, inputs, seed=923, trials=1_000_000)
    out = mc.outputs[0]
    # Exact reference: Y = 2√3 (S - 2), S ~ Irwin-Hall(4): 97.5 % quantile 3.8794.
    exact = 2 * SQRT3 * (irwin_hall_quantile(0.975, 4) - 2.0)
    assert exact == pytest.approx(3.88, abs=0.005)  # JCGM 101 Table 4
    # The density of Y at 3.88 is 0.031, so se(quantile) = 0.005; 5 se.
    assert out.probabilistically_symmetric.high == pytest.approx(exact, abs=0.025)
    assert out.probabilistically_symmetric.low == pytest.approx(-exact, abs=0.025)
    assert out.standard_uncertainty == pytest.approx(2.0, abs=0.006)
    g = propagate_gum(additive, inputs).outputs[0]
    assert g.standard_uncertainty == pytest.approx(2.0, rel=1e-9)
    assert g.interval.high == pytest.approx(3.92, abs=0.0005)
    # GUM overstates by 0.04: within δ = 0.05 at n_dig = 2, not within 0.005 at n_dig = 3.
    assert not validate_gum(propagate_gum(additive, inputs), mc, n_dig=3).validated


def test_9_2_4_one_dominant_rectangular_input() -> None:
    inputs = [Rectangular.from_centre(0.0, SQRT3)] * 3 + [Rectangular.from_centre(0.0, 10 * SQRT3)]
    mc = monte_carlo(additive, inputs, seed=924, trials=1_000_000)
    out = mc.outputs[0]
    # Published: u = 10.15, interval ±17.0. se(u) = 0.006, se(quantile) = 0.01.
    assert out.standard_uncertainty == pytest.approx(10.15, abs=0.005 + 0.03)
    assert out.probabilistically_symmetric.high == pytest.approx(17.0, abs=0.05 + 0.05)
    assert out.probabilistically_symmetric.low == pytest.approx(-17.0, abs=0.05 + 0.05)
    gum = propagate_gum(additive, inputs)
    assert gum.outputs[0].standard_uncertainty == pytest.approx(math.sqrt(103.0), rel=1e-9)
    assert gum.outputs[0].interval.high == pytest.approx(19.9, abs=0.05)
    check = validate_gum(gum, mc, n_dig=2)
    # u = 10 × 10^0 so δ = 0.5, while the GUM interval is ~2.9 too wide at each end.
    assert check.delta == pytest.approx(0.5)
    assert not check.validated and min(check.d_low, check.d_high) > 2.5


def test_9_3_mass_calibration() -> None:
    mc = monte_carlo(mass_model, MASS_INPUTS, seed=93, trials=2_000_000, keep_samples=False)
    out = mc.outputs[0]
    # Reference from a 10^7-trial run: y = 1.2340 mg, u = 0.0755 mg, shortest
    # [1.0844, 1.3835] mg. Spread over 8 seeds at 10^6 trials: se(y) = 6e-5,
    # se(u) = 1e-4, se(endpoints) = 5e-4 mg; at 2×10^6 divide by √2, allow ~4 se.
    assert out.estimate == pytest.approx(1.2340, abs=0.0002)
    assert out.standard_uncertainty == pytest.approx(0.0755, abs=0.0003)
    assert out.shortest.low == pytest.approx(1.0844, abs=0.0015)
    assert out.shortest.high == pytest.approx(1.3835, abs=0.0015)
    gum = propagate_gum(mass_model, MASS_INPUTS)
    g = gum.outputs[0]
    # First-order GUM: the buoyancy terms have zero sensitivity at ρ_W = ρ_R, so
    # u = sqrt(0.050² + 0.020²) = 0.0539 mg; finite differences on 10^5 mg values
    # lose ~1e-8 relative, hence the tolerances.
    assert g.estimate == pytest.approx(1.2340, abs=1e-8)
    assert g.standard_uncertainty == pytest.approx(math.hypot(0.050, 0.020), rel=1e-6)
    assert g.interval.low == pytest.approx(1.1285, abs=0.00005)
    assert g.interval.high == pytest.approx(1.3395, abs=0.00005)
    np.testing.assert_allclose(gum.sensitivities[0, 2:], 0.0, atol=1e-3)
    check = validate_gum(gum, mc, n_dig=2)
    assert check.delta == pytest.approx(0.0005)  # u = 54 × 10^-3
    assert not check.validated and min(check.d_low, check.d_high) > 0.04
