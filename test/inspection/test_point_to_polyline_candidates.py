"""point_to_polyline prunes the segments it tries (a vertex tree): the same answer, bit for bit,
as trying every segment (the brute force written out here)."""

from __future__ import annotations

import numpy as np
import pytest

from robocal_uncertainty.inspection import section
from robocal_uncertainty.inspection.section import point_to_polyline


def _brute_force(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    start = b[:-1]
    edge = b[1:] - start
    length2 = np.maximum((edge**2).sum(axis=1), 1e-300)
    rel = a[:, np.newaxis, :] - start[np.newaxis, :, :]
    t = np.clip((rel * edge).sum(axis=-1) / length2, 0.0, 1.0)
    dist2 = ((rel - t[..., np.newaxis] * edge) ** 2).sum(axis=-1)
    segment = np.argmin(dist2, axis=1)
    rows = np.arange(a.shape[0])
    foot = t[rows, segment]
    interior = ~(((segment == 0) & (foot <= 0.0)) | ((segment == edge.shape[0] - 1) & (foot >= 1.0)))
    return np.sqrt(dist2[rows, segment]), segment, interior


@pytest.mark.parametrize("seed", range(4))
def test_pruned_search_equals_every_segment(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # A blade-like side: a wavy arc with uneven spacing (a few long segments), and points on
    # both sides, beyond its ends, and exactly on vertices (ties between two segments).
    u = np.sort(rng.uniform(0.0, 1.0, 600)) ** 1.5
    polyline = np.column_stack([0.4 * u, 0.03 * np.sin(3.0 * u) + 1e-5 * rng.standard_normal(u.size)])
    points = np.concatenate(
        [
            polyline[rng.integers(0, u.size, 50)],
            rng.uniform([-0.05, -0.05], [0.45, 0.08], (700, 2)),
        ]
    )
    assert points.shape[0] * (u.size - 1) > section._ALL_SEGMENTS  # the pruned path runs
    got = point_to_polyline(points, polyline)
    want = _brute_force(points, polyline)
    for g, w in zip(got, want):
        assert np.array_equal(g, w)
