"""compare_frames: the rigid move between predicted and measured positions (issue 18)."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.core.frame_check import compare_frames
from robocal_uncertainty.core.robot_model import rpy_to_matrix
from robocal_uncertainty.errors import InputError


def _points(n: int = 300) -> np.ndarray:
    return np.random.default_rng(1).uniform(-0.8, 0.8, (n, 3)) + np.array([2.0, -0.5, 0.3])


def test_a_known_move_is_recovered_and_named() -> None:
    """Tracker moved by a known rotation (angle analytic: |rotation vector| for small rpy is
    within 1e-6 rad of the norm) and translation; measured with 0.1 mm noise."""
    p = _points()
    rot = rpy_to_matrix(np.array([0.002, -0.001, 0.003]))
    t = np.array([0.004, -0.002, 0.001])
    m = p @ rot.T + t + np.random.default_rng(2).normal(0.0, 1e-4, p.shape)
    c = compare_frames(p, m, limit=1e-3)
    angle = np.arccos((np.trace(rot) - 1.0) / 2.0)
    assert c.angle == pytest.approx(angle, abs=5e-5)
    centroid = p.mean(axis=0)
    assert c.shift == pytest.approx(np.linalg.norm(rot @ centroid + t - centroid), abs=5e-5)
    assert c.rms_after == pytest.approx(np.sqrt(3) * 1e-4, rel=0.1)  # only the noise is left
    assert c.moved
    line = c.describe()
    assert f"{c.shift * 1e3:.2f} mm and {c.angle * 1e3:.2f} mrad" in line and "\n" not in line


def test_noise_alone_is_no_move() -> None:
    p = _points()
    m = p + np.random.default_rng(3).normal(0.0, 2e-4, p.shape)
    c = compare_frames(p, m, limit=2e-4)
    assert not c.moved
    assert c.displacement_rms < 1e-4  # a fit over 300 points averages the noise out


def test_an_error_the_rigid_fit_does_not_explain_is_no_move() -> None:
    """Another robot, or a wrong model: a smooth non-rigid error of 3 mm with a small rigid part
    (0.5 mm) beyond the limit, but the fit leaves most of the error: not a frame move."""
    p = _points()
    bend = 3e-3 * np.stack((np.sin(3 * p[:, 1]), np.cos(2 * p[:, 0]), np.sin(2 * p[:, 2] + 1)), axis=1)
    m = p + bend
    c = compare_frames(p, m, limit=1e-4)
    assert c.displacement_rms > c.limit
    assert c.rms_after > 0.5 * c.rms_before
    assert not c.moved


@pytest.mark.parametrize(
    ("predicted", "measured", "limit", "match"),
    [
        (np.zeros((5, 3)), np.zeros((4, 3)), 1e-3, "two \\(n, 3\\) arrays"),
        (np.zeros((2, 3)), np.zeros((2, 3)), 1e-3, "at least 3 points"),
        (np.full((4, 3), np.nan), np.zeros((4, 3)), 1e-3, "finite"),
        (np.eye(3), np.eye(3), 0.0, "positive length"),
    ],
)
def test_bad_input_is_one_line(predicted, measured, limit, match) -> None:
    with pytest.raises(InputError, match=match):
        compare_frames(predicted, measured, limit)
