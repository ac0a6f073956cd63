"""Shared geometry for the inspection tests: analytic sections and the shipped blades.

A module of its own (not conftest) so that tests import it by a name no other folder uses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

DATA = Path(__file__).parent / "data"
ROTOR37 = DATA / "nasa_rotor37_blade_geometry.dat"
CASCADE = DATA / "dfvlr_l030-4_cascade_profile.dat"
ROTOR37_SCALE = 7.14
"""Rotor 37 surface 2 scaled to the seed's blade: maximum thickness 30.37 mm (seed 30.365 mm)."""


def stadium(radius: float, length: float, n_arc: int, n_side: int) -> NDArray[np.float64]:
    """Counterclockwise stadium: semicircles of ``radius`` [m] at x = 0 and x = ``length``,
    joined by straight sides y = ±radius; extreme points (-radius, 0), (length + radius, 0)
    and the side midpoints are samples."""
    right = np.linspace(-np.pi / 2, np.pi / 2, 2 * n_arc + 1)[:-1]
    left = right + np.pi
    top = np.linspace(length, 0.0, 2 * n_side + 1)[1:-1]
    bottom = top[::-1]
    return np.concatenate(
        [
            np.column_stack([length + radius * np.cos(right), radius * np.sin(right)]),
            np.column_stack([top, np.full(top.size, radius)]),
            np.column_stack([radius * np.cos(left), radius * np.sin(left)]),
            np.column_stack([bottom, np.full(bottom.size, -radius)]),
        ]
    )


def ellipse(a: float, b: float, n: int) -> NDArray[np.float64]:
    """Counterclockwise ellipse with semi-axes a (x) > b (y) [m], n points (n divisible by 4,
    so the four vertices are samples)."""
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([a * np.cos(t), b * np.sin(t)])
