"""Fixtures of the inspection tests (their data lives in inspection_data)."""

from __future__ import annotations

import pytest
from inspection_data import ROTOR37, ROTOR37_SCALE, stadium

from robocal_uncertainty.inspection.nominal_curve import NominalCurve
from robocal_uncertainty.inspection.point_cloud import NominalSection, read_rotor37_section


@pytest.fixture(scope="session")
def rotor37_curve() -> NominalCurve:
    """Rotor 37 surface 2 at the seed's size."""
    return NominalCurve(read_rotor37_section(ROTOR37, 2, scale=ROTOR37_SCALE))


@pytest.fixture(scope="session")
def stadium_curve() -> NominalCurve:
    """A 60 mm x 10 mm stadium (edge radius 5 mm) sampled every ~0.1 mm."""
    return NominalCurve(NominalSection(stadium(5e-3, 50e-3, 80, 250), "stadium"))
