"""Per-configuration summary of an evaluation, for reports with many test configurations.

A report on one test configuration shows everything about it; a report on hundreds
shows where the uncertainty is largest. :func:`summarize_configurations` reduces each
configuration to a few numbers (position, u per axis, u_pos, reach, JCGM 102 region
semi-axes, GUM verdict) and orders them worst first; :func:`select_configurations`
turns the ``histograms=`` argument of :func:`~robocal_uncertainty.report.write_report`
into configuration indices; :func:`write_configurations_csv` writes the full table.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.calibration import CalibrationUncertainty

__all__ = [
    "DEFAULT_HISTOGRAMS",
    "DETAIL_LIMIT",
    "ConfigurationSummary",
    "HistogramSelection",
    "select_configurations",
    "summarize_configurations",
    "write_configurations_csv",
]

Array = NDArray[np.float64]

DETAIL_LIMIT = 10
"""Up to this many test configurations, a report shows every one in full (Table 2, GUM
comparison, budget and histograms each); beyond it, summary tables and plots plus full
detail for a selection (see :data:`DEFAULT_HISTOGRAMS`)."""

DEFAULT_HISTOGRAMS = 6
"""Configurations beyond :data:`DETAIL_LIMIT` that get histograms by default: the first
this many, plus the worst (largest u_pos)."""

HistogramSelection = int | str | Sequence[int] | None
"""``None`` (default rule), a count of first configurations, ``"all"``, or 0-based indices."""


@dataclass(frozen=True)
class ConfigurationSummary:
    """A few numbers per test configuration, ordered worst first by :attr:`order`.

    Attributes
    ----------
    position : ndarray, shape (n_test, 3) [m]
        Mean tool position in the result's output frame.
    standard_uncertainty : ndarray, shape (n_test, 3) [m]
        u(x), u(y), u(z).
    expanded_uncertainty : ndarray, shape (n_test, 3) [m]
        U(x), U(y), U(z) at the result's coverage probability.
    position_uncertainty : ndarray, shape (n_test,) [m]
        u_pos = sqrt(u(x)² + u(y)² + u(z)²).
    reach : ndarray, shape (n_test,) [m]
        Distance of the tool from the origin of the robot base frame (calibrated model).
    region_semi_axes : ndarray, shape (n_test, 3) [m]
        Semi-axes of the JCGM 102 coverage ellipsoid, largest first (NaN where the
        region is degenerate).
    gum_validated : ndarray of bool, shape (n_test,)
        The GUM is validated on all three axes (False where not applicable).
    order : ndarray of int, shape (n_test,)
        0-based configuration indices sorted by u_pos, largest first (ties by index).
    """

    position: Array
    standard_uncertainty: Array
    expanded_uncertainty: Array
    position_uncertainty: Array
    reach: Array
    region_semi_axes: Array
    gum_validated: NDArray[np.bool_]
    order: NDArray[np.intp]

    @property
    def worst(self) -> int:
        """0-based index of the configuration with the largest u_pos."""
        return int(self.order[0])

    def __len__(self) -> int:
        return int(self.position.shape[0])


def _reach(result: CalibrationUncertainty) -> Array:
    cal = result.calibration
    layout = cal.model.layout
    params = np.array(cal.estimate, dtype=np.float64)
    b0 = layout.base_index
    params[b0 : b0 + 6] = 0.0  # the tool in the robot base frame
    joints = np.array([p.joint_positions for p in result.poses], dtype=np.float64)
    return np.asarray(np.linalg.norm(forward_points(layout, params, joints), axis=-1), dtype=np.float64)


def summarize_configurations(result: CalibrationUncertainty) -> ConfigurationSummary:
    """Reduce every test configuration of `result` to the numbers of :class:`ConfigurationSummary`.

    Parameters
    ----------
    result : CalibrationUncertainty

    Returns
    -------
    ConfigurationSummary
    """
    n = len(result.poses)
    position = np.array([p.mean for p in result.poses], dtype=np.float64).reshape(n, 3)
    u = np.array([[a.standard_uncertainty for a in p.axes] for p in result.poses], dtype=np.float64).reshape(n, 3)
    big = np.array([[a.expanded_uncertainty for a in p.axes] for p in result.poses], dtype=np.float64).reshape(n, 3)
    semi = np.full((n, 3), np.nan)
    for i, pose in enumerate(result.poses):
        if pose.region is not None:
            eig = np.clip(np.linalg.eigvalsh(pose.region.covariance), 0.0, None)
            semi[i] = pose.region.coverage_factor * np.sqrt(eig[::-1])
    validated = np.array([p.gum.applicable and all(p.gum.validated) for p in result.poses], dtype=bool)
    u_pos = np.linalg.norm(u, axis=1)
    # Stable sort on -u_pos: equal uncertainties keep their configuration order.
    order = np.argsort(-u_pos, kind="stable")
    return ConfigurationSummary(
        position=position,
        standard_uncertainty=u,
        expanded_uncertainty=big,
        position_uncertainty=u_pos,
        reach=_reach(result),
        region_semi_axes=semi,
        gum_validated=validated,
        order=order,
    )


def select_configurations(histograms: HistogramSelection, n_test: int, worst: int = 0) -> tuple[int, ...]:
    """0-based indices of the test configurations that get per-configuration figures.

    Parameters
    ----------
    histograms : None, int, "all" or sequence of int
        ``None``: every configuration when there are at most :data:`DETAIL_LIMIT`,
        otherwise the first :data:`DEFAULT_HISTOGRAMS` and `worst`. An int ``N >= 0``: the
        first N. ``"all"``: every configuration. A sequence: those 0-based indices.
    n_test : int
        Number of test configurations.
    worst : int
        0-based index of the worst configuration (added by the default rule).

    Returns
    -------
    tuple of int
        Sorted, without repeats.

    Raises
    ------
    ConfigError
        A negative count, another string than ``"all"``, or an index outside
        ``[0, n_test)``.
    """
    if histograms is None:
        if n_test <= DETAIL_LIMIT:
            return tuple(range(n_test))
        return tuple(sorted({*range(DEFAULT_HISTOGRAMS), worst}))
    if isinstance(histograms, str):
        if histograms != "all":
            msg = f"histograms must be a count, 'all' or a sequence of configuration indices, got {histograms!r}"
            raise ConfigError(msg)
        return tuple(range(n_test))
    if isinstance(histograms, bool):
        msg = f"histograms must be a count, 'all' or a sequence of configuration indices, got {histograms!r}"
        raise ConfigError(msg)
    if isinstance(histograms, (int, np.integer)):
        if histograms < 0:
            msg = f"histograms must be a count >= 0, got {histograms}"
            raise ConfigError(msg)
        return tuple(range(min(int(histograms), n_test)))
    chosen: set[int] = set()
    for value in histograms:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value < n_test:
            msg = (
                f"histograms index {value!r} is not a 0-based configuration index in [0, {n_test}) "
                f"({n_test} test configuration(s))"
            )
            raise ConfigError(msg)
        chosen.add(int(value))
    return tuple(sorted(chosen))


def _num(value: float | None, scale: float) -> str:
    if value is None:  # e.g. no coverage factor where the standard uncertainty is zero
        return ""
    v = float(value) * scale
    return f"{v:.9g}" if math.isfinite(v) else ""


def write_configurations_csv(
    path: str | Path,
    result: CalibrationUncertainty,
    summary: ConfigurationSummary | None = None,
) -> Path:
    """Write one row per test configuration (1-based ``configuration``) to a CSV file.

    Columns, lengths in the unit named in the header: joints (deg), mean position (mm),
    reach (mm), u and U per axis and u_pos (µm), coverage factor, both coverage
    intervals per axis (mm), JCGM 102 region k_p and semi-axes (µm), GUM u per axis (µm)
    and verdict per axis (``yes``/``no``/``n/a``). Empty cells stand for missing values.

    Parameters
    ----------
    path : str or Path
        CSV file to write (UTF-8).
    result : CalibrationUncertainty
    summary : ConfigurationSummary, optional
        Of `result`; computed when omitted.

    Returns
    -------
    Path
    """
    summary = summary or summarize_configurations(result)
    n_joints = len(result.poses[0].joint_positions) if result.poses else 0
    header = ["configuration", *(f"joint{j + 1}_deg" for j in range(n_joints))]
    header += [f"{a}_mm" for a in "xyz"] + ["reach_mm"]
    header += [f"u_{a}_um" for a in "xyz"] + ["u_pos_um"]
    header += [f"U_{a}_um" for a in "xyz"] + [f"k_{a}" for a in "xyz"]
    for axis in "xyz":
        header += [f"sym_low_{axis}_mm", f"sym_high_{axis}_mm", f"short_low_{axis}_mm", f"short_high_{axis}_mm"]
    header += ["region_k_p", "region_a1_um", "region_a2_um", "region_a3_um"]
    header += [f"gum_u_{a}_um" for a in "xyz"] + [f"gum_validated_{a}" for a in "xyz"]
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for i, pose in enumerate(result.poses):
            row = [str(i + 1), *(f"{v:.6f}" for v in np.degrees(pose.joint_positions))]
            row += [_num(v, 1e3) for v in summary.position[i]] + [_num(summary.reach[i], 1e3)]
            row += [_num(v, 1e6) for v in summary.standard_uncertainty[i]]
            row += [_num(summary.position_uncertainty[i], 1e6)]
            row += [_num(v, 1e6) for v in summary.expanded_uncertainty[i]]
            row += [_num(a.coverage_factor, 1.0) for a in pose.axes]
            for a in pose.axes:
                sym, short = a.probabilistically_symmetric, a.shortest
                row += [_num(sym.low, 1e3), _num(sym.high, 1e3), _num(short.low, 1e3), _num(short.high, 1e3)]
            k_p = pose.region.coverage_factor if pose.region is not None else math.nan
            row += [_num(k_p, 1.0), *(_num(v, 1e6) for v in summary.region_semi_axes[i])]
            row += [_num(v, 1e6) for v in pose.gum.standard_uncertainty]
            verdicts = pose.gum.validated if pose.gum.applicable else (None, None, None)
            row += ["n/a" if v is None else ("yes" if v else "no") for v in verdicts]
            writer.writerow(row)
    return out
