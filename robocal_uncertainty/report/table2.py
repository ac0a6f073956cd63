"""Text tables in the layout of the seed's Table 2, and a per-source budget.

Numbers are rounded to their uncertainty: the standard uncertainty keeps two
significant digits, and every other length of the same axis (value, expanded
uncertainty, interval endpoints) keeps the same number of decimals, like
suncal's ``Number(value, matchto=uncert)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from robocal_uncertainty.errors import ConfigError
from robocal_uncertainty.uncertainty.calibration_mc import (
    CalibrationUncertainty,
    PoseUncertainty,
)

__all__ = [
    "LENGTH_UNITS",
    "budget_rows",
    "decimals_for",
    "format_budget",
    "format_significant",
    "format_table2",
    "gum_verdict",
    "pose_header",
    "round_to_uncertainty",
    "table2_rows",
]

LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e3, "µm": 1e6, "um": 1e6}
"""Factor from metres to each display unit."""

_INTERVAL_NAMES = {
    "probabilistically_symmetric": "probabilistically symmetric",
    "shortest": "shortest",
}


def _scale(unit: str) -> float:
    try:
        return LENGTH_UNITS[unit]
    except KeyError as err:
        msg = f"unit must be one of {', '.join(LENGTH_UNITS)}, got {unit!r}"
        raise ConfigError(msg) from err


def decimals_for(uncertainty: float, digits: int = 2) -> int | None:
    """Decimals that leave `digits` significant digits in `uncertainty`.

    Negative when the uncertainty is large (-1 rounds to tens); None when the
    uncertainty is zero or not finite.
    """
    if isinstance(digits, bool) or not isinstance(digits, int) or digits < 1:
        msg = f"digits must be an integer >= 1, got {digits!r}"
        raise ConfigError(msg)
    u = abs(float(uncertainty))
    if u == 0.0 or not math.isfinite(u):
        return None
    decimals = digits - 1 - math.floor(math.log10(u))
    # Rounding can carry into one more digit (0.0996 -> 0.100): keep `digits` digits.
    if abs(round(u, decimals)) >= 10.0 ** (digits - decimals):
        decimals -= 1
    return decimals


def _fixed(value: float, decimals: int) -> str:
    if decimals >= 0:
        return f"{value:.{decimals}f}"
    step = 10.0 ** (-decimals)
    return f"{round(value / step) * step:.0f}"


def round_to_uncertainty(value: float, uncertainty: float, digits: int = 2) -> str:
    """Format `value` with the decimals of `uncertainty` at `digits` significant digits.

    Parameters
    ----------
    value : float
        Number to format, in any unit.
    uncertainty : float
        Its uncertainty, in the same unit.
    digits : int
        Significant digits kept in the uncertainty.

    Returns
    -------
    str
        E.g. ``round_to_uncertainty(228.91951, 0.4774) == "228.92"``. With a zero or
        non-finite uncertainty the value gets 6 significant digits; a non-finite value
        gives ``"n/a"``.
    """
    v = float(value)
    if not math.isfinite(v):
        return "n/a"
    decimals = decimals_for(uncertainty, digits)
    if decimals is None:
        return f"{v:.6g}"
    return _fixed(v, decimals)


def format_significant(value: float | None, digits: int = 2) -> str:
    """`value` with `digits` significant digits (``"n/a"`` for None/NaN)."""
    if value is None or not math.isfinite(float(value)):
        return "n/a"
    v = float(value)
    if v == 0.0:
        return "0"
    return round_to_uncertainty(v, v, digits)


def gum_verdict(pose: PoseUncertainty) -> str:
    """One-line GUM validation verdict per axis (JCGM 101 §8)."""
    if not pose.gum.applicable:
        return "not applicable (non-smooth source enabled)"
    marks = [f"{ax} {'yes' if ok else 'no'}" for ax, ok in zip("xyz", pose.gum.validated)]
    return ", ".join(marks)


def pose_header(result: CalibrationUncertainty, index: int) -> list[str]:
    """Header lines of one test configuration: joints, trials, p, interval, seed, sources."""
    pose = result.poses[index]
    joints = ", ".join(f"{v:.4f}" for v in np.degrees(pose.joint_positions))
    kind = pose.axes[0].expanded_from
    adaptive = ""
    if result.adaptive is not None:
        adaptive = " (adaptive, " + ("converged" if result.converged else "NOT converged") + ")"
    return [
        f"Test configuration {index + 1} of {len(result.poses)}",
        f"  joints / deg: ({joints})",
        (f"  trials: {result.n_trials}{adaptive}   seed: {result.seed}   block size: {result.block_size}"),
        (
            f"  coverage probability: {100 * result.coverage_probability:g} %   "
            f"interval: {_INTERVAL_NAMES.get(kind, kind)}"
        ),
        f"  sources: {', '.join(result.settings.sources)}",
        f"  GUM validated (JCGM 101 §8): {gum_verdict(pose)}",
    ]


def table2_rows(pose: PoseUncertainty, unit: str = "mm") -> list[tuple[str, list[str]]]:
    """Rows of Table 2 for one pose: (label with unit, [x, y, z] cells)."""
    s = _scale(unit)
    rows: list[tuple[str, list[str]]] = [
        (f"Output value / {unit}", []),
        (f"Standard uncertainty / {unit}", []),
        (f"Expanded uncertainty / {unit}", []),
        (f"Coverage interval / {unit}", []),
        ("Relative expanded uncertainty / %", []),
    ]
    for axis in pose.axes:
        u = axis.standard_uncertainty * s
        interval = axis.interval
        rows[0][1].append(round_to_uncertainty(axis.estimate * s, u))
        rows[1][1].append(round_to_uncertainty(u, u))
        rows[2][1].append(round_to_uncertainty(axis.expanded_uncertainty * s, u))
        low = round_to_uncertainty(interval.low * s, u)
        high = round_to_uncertainty(interval.high * s, u)
        rows[3][1].append(f"({low}, {high})")
        rel = axis.relative_expanded_uncertainty
        rows[4][1].append(format_significant(None if rel is None else 100.0 * rel))
    return rows


def _grid(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]
    out = ["  ".join(cell.ljust(w) if c == 0 else cell.rjust(w) for c, (cell, w) in enumerate(zip(header, widths)))]
    out.append("  ".join("-" * w for w in widths))
    out.extend(
        "  ".join(cell.ljust(w) if c == 0 else cell.rjust(w) for c, (cell, w) in enumerate(zip(row, widths)))
        for row in rows
    )
    return out


def format_table2(result: CalibrationUncertainty, *, unit: str = "mm") -> str:
    """Seed Table 2 for every test configuration, as plain text.

    Parameters
    ----------
    result : CalibrationUncertainty
    unit : {"mm", "m", "µm", "um"}
        Display unit of lengths (the result is in metres).

    Returns
    -------
    str
        One block per test configuration: a header (joints in degrees, trials, coverage
        probability, interval type, seed, sources, GUM verdict) and the rows output value,
        standard uncertainty, expanded uncertainty, coverage interval and relative
        expanded uncertainty (%) in columns x, y, z.
    """
    _scale(unit)
    blocks = []
    for i, pose in enumerate(result.poses):
        lines = pose_header(result, i)
        rows = [[label, *cells] for label, cells in table2_rows(pose, unit)]
        lines.extend(_grid(["Quantity", "x", "y", "z"], rows))
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks) + "\n"


def budget_rows(budget: Mapping[str, CalibrationUncertainty], pose: int = 0) -> list[list[str]]:
    """Rows [source, u_x, u_y, u_z, u_pos] in µm (2 significant digits) for one pose."""
    rows = []
    for name, res in budget.items():
        if not 0 <= pose < len(res.poses):
            msg = f"budget entry {name!r} has no test configuration {pose}"
            raise ConfigError(msg)
        u = np.array([a.standard_uncertainty for a in res.poses[pose].axes]) * 1e6
        rows.append(
            [
                name,
                *(format_significant(v) for v in u),
                format_significant(float(np.linalg.norm(u))),
            ]
        )
    return rows


def format_budget(budget: Mapping[str, CalibrationUncertainty]) -> str:
    """Per-source uncertainty budget, one table per test configuration.

    Parameters
    ----------
    budget : mapping of str to CalibrationUncertainty
        Label (usually the single source run) to its result; all results must share
        the same test configurations.

    Returns
    -------
    str
        Rows = sources run alone; columns u_x, u_y, u_z and the root-sum-square
        u_pos = sqrt(u_x² + u_y² + u_z²), in µm with two significant digits.
    """
    if not budget:
        return "(empty budget)\n"
    n_test = min(len(r.poses) for r in budget.values())
    header = ["Source", "u_x / µm", "u_y / µm", "u_z / µm", "u_pos / µm"]
    blocks = []
    for i in range(n_test):
        lines = [f"Uncertainty budget, test configuration {i + 1} of {n_test}"]
        lines.extend(_grid(header, budget_rows(budget, i)))
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks) + "\n"
