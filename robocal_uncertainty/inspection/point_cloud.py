"""Point clouds of one blade section and nominal section geometry, read into SI units.

A CMM export is a text table of ``x y z`` or ``x y z i j k`` rows (coordinates, then the probe
vector), separated by commas, tabs, semicolons or blanks (detected from the first data row).
Its length unit is stated in a comment line (``# unit: mm``), in the column names
(``x[mm],y[mm],z[mm]``) or given by the caller; it is never guessed, and a file with neither is
refused. Everything returned is in metres.

Nominal sections are ordered closed curves in the section plane: the same text formats (2, 3
or 6 columns, in order along the contour), or the two shipped blade geometries (NASA Rotor 37,
DFVLR L030-4 cascade; see ``shared/data/blade_sections/README.md``). The section plane is the
``x y`` plane: ``x`` axial, ``y`` circumferential (tangential); ``z`` is the section height.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal_uncertainty.errors import InputError

__all__ = [
    "LENGTH_UNITS",
    "NominalSection",
    "PointCloud",
    "length_unit_factor",
    "read_cascade_profile",
    "read_nominal_section",
    "read_point_cloud",
    "read_rotor37_section",
]

LENGTH_UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 1e-2,
    "mm": 1e-3,
    "um": 1e-6,
    "µm": 1e-6,
    "micron": 1e-6,
    "in": 0.0254,
    "inch": 0.0254,
}
"""Length units accepted in files and arguments, as metres per unit."""

_MIN_NOMINAL_POINTS = 8
_UNIT_COMMENT = re.compile(r"\bunits?\s*[:=]\s*([A-Za-zµ]+)", re.IGNORECASE)
_UNIT_COLUMN = re.compile(r"[\[(]\s*([A-Za-zµ]+)\s*[\])]")
_COMMENT_PREFIXES = ("#", "//", ";", "!")


def length_unit_factor(unit: str, *, what: str = "unit") -> float:
    """Metres per ``unit`` (one of :data:`LENGTH_UNITS`), or an InputError naming it."""
    key = unit.strip()
    factor = LENGTH_UNITS.get(key, LENGTH_UNITS.get(key.lower()))
    if factor is None:
        msg = f"{what} must be one of {sorted(LENGTH_UNITS)}, got {unit!r}"
        raise InputError(msg)
    return factor


def _readonly(array: NDArray[np.float64]) -> NDArray[np.float64]:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Measured points of one section, in metres.

    A bag reader (``sensor_msgs/msg/PointCloud2``) produces the same object: ``points`` from the
    x/y/z fields scaled to metres, ``probe_vectors`` from normal fields when present.

    Attributes
    ----------
    points : ndarray, shape (n, 3) [m]
        Measured coordinates; x axial, y circumferential, z section height.
    probe_vectors : ndarray, shape (n, 3), or None
        Unit probe (approach) vectors, dimensionless; None when the export has none.
    source : str
        Where the points came from (a path, a topic), for messages and reports.
    frame_id : str
        Coordinate frame of the points (a PointCloud2 header's ``frame_id``); empty for files.
    """

    points: NDArray[np.float64]
    probe_vectors: NDArray[np.float64] | None = None
    source: str = ""
    frame_id: str = ""

    def __post_init__(self) -> None:
        name = self.source or "point cloud"
        points = np.array(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 1:
            msg = f"{name}: points must have shape (n, 3) with n >= 1, got {points.shape}"
            raise InputError(msg)
        _check_finite(name, "points", points)
        object.__setattr__(self, "points", _readonly(points))
        if self.probe_vectors is not None:
            vectors = np.array(self.probe_vectors, dtype=np.float64)
            if vectors.shape != points.shape:
                msg = f"{name}: probe_vectors must have shape {points.shape}, got {vectors.shape}"
                raise InputError(msg)
            _check_finite(name, "probe_vectors", vectors)
            norms = np.linalg.norm(vectors, axis=1)
            if (norms < 1e-9).any():
                row = int(np.argmax(norms < 1e-9))
                msg = f"{name}: probe vector of point {row} has zero length"
                raise InputError(msg)
            object.__setattr__(self, "probe_vectors", _readonly(vectors / norms[:, np.newaxis]))

    @property
    def n_points(self) -> int:
        """Number of points."""
        return int(self.points.shape[0])

    @property
    def xy(self) -> NDArray[np.float64]:
        """Coordinates in the section plane, shape (n, 2) [m]."""
        return self.points[:, :2]


@dataclass(frozen=True, eq=False)
class NominalSection:
    """Nominal (design) section: an ordered closed contour in the section plane.

    The constructor drops a repeated closing point and reorders the contour counterclockwise,
    so the outward normal is the tangent turned clockwise.

    Attributes
    ----------
    points : ndarray, shape (n, 2) [m]
        Contour points in order, counterclockwise, not repeating the first point.
    source : str
        Where the geometry came from.
    """

    points: NDArray[np.float64]
    source: str = ""

    def __post_init__(self) -> None:
        name = self.source or "nominal section"
        points = np.array(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 2:
            msg = f"{name}: points must have shape (n, 2), got {points.shape}"
            raise InputError(msg)
        _check_finite(name, "points", points)
        if points.shape[0] > 1 and np.allclose(points[0], points[-1], rtol=0.0, atol=1e-12):
            points = points[:-1]
        if points.shape[0] < _MIN_NOMINAL_POINTS:
            msg = f"{name}: a section needs at least {_MIN_NOMINAL_POINTS} contour points, got {points.shape[0]}"
            raise InputError(msg)
        steps = np.linalg.norm(np.diff(points, axis=0, append=points[:1]), axis=1)
        size = float(np.ptp(points, axis=0).max())
        if (steps <= 1e-12 * max(size, 1e-300)).any():
            row = int(np.argmax(steps <= 1e-12 * max(size, 1e-300)))
            msg = f"{name}: contour point {row} repeats its successor; a nominal contour needs distinct points"
            raise InputError(msg)
        _check_simple(name, points)
        x, y = points[:, 0], points[:, 1]
        area = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
        if area < 0:
            points = np.concatenate([points[:1], points[:0:-1]])
        object.__setattr__(self, "points", _readonly(np.ascontiguousarray(points)))

    @property
    def n_points(self) -> int:
        """Number of contour points."""
        return int(self.points.shape[0])

    def scaled(self, factor: float) -> NominalSection:
        """The section scaled about the origin by ``factor`` (> 0, dimensionless)."""
        if not (math.isfinite(factor) and factor > 0):
            msg = f"scale factor must be positive and finite, got {factor!r}"
            raise InputError(msg)
        return NominalSection(self.points * factor, f"{self.source} ×{factor:g}")


def _check_finite(name: str, what: str, values: NDArray[np.float64]) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad.any(axis=1)))
        msg = f"{name}: {what} contain {int(bad.sum())} NaN/inf values (first in point {row})"
        raise InputError(msg)


def _check_simple(name: str, points: NDArray[np.float64]) -> None:
    """Raise when two non-adjacent edges of the closed polygon cross (checked in row blocks)."""
    n = points.shape[0]
    a = points
    b = np.roll(points, -1, axis=0)
    d = b - a
    index = np.arange(n)
    for start in range(0, n, 256):
        rows = slice(start, min(start + 256, n))
        # Edge i (rows) against edge j (all): j's end points on either side of line i, and
        # i's end points on either side of line j.
        cross_i = _sides(a[rows], d[rows], a, b)
        cross_j = _sides(a, d, a[rows], b[rows]).T
        gap = np.abs(index[rows, np.newaxis] - index[np.newaxis, :])
        crossing = cross_i & cross_j & (gap > 1) & (gap < n - 1)
        if crossing.any():
            i, j = np.argwhere(crossing)[0]
            msg = f"{name}: the contour intersects itself (edges {int(i) + start} and {int(j)} cross)"
            raise InputError(msg)


def _sides(
    origin: NDArray[np.float64], direction: NDArray[np.float64], p: NDArray[np.float64], q: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Whether p_j and q_j lie strictly on opposite sides of line i, shape (len(origin), len(p))."""
    rel_p = p[np.newaxis, :, :] - origin[:, np.newaxis, :]
    rel_q = q[np.newaxis, :, :] - origin[:, np.newaxis, :]
    side_p = direction[:, np.newaxis, 0] * rel_p[..., 1] - direction[:, np.newaxis, 1] * rel_p[..., 0]
    side_q = direction[:, np.newaxis, 0] * rel_q[..., 1] - direction[:, np.newaxis, 1] * rel_q[..., 0]
    return np.asarray(side_p * side_q < 0)


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return [token.strip() for token in line.split(delimiter)]


def _detect_delimiter(line: str) -> str | None:
    for candidate in (",", "\t", ";"):
        if candidate in line:
            return candidate
    return None


def _parse_float(token: str) -> float | None:
    try:
        return float(token)
    except ValueError:
        return None


def _read_table(path: Path, unit: str | None, columns: tuple[int, ...]) -> tuple[NDArray[np.float64], float, int]:
    """Numeric rows of a CMM-style text table, the metres-per-unit factor and the column count."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror or err}"
        raise InputError(msg) from err
    stated: list[tuple[str, int]] = []
    rows: list[list[float]] = []
    delimiter: str | None = None
    width: int | None = None
    names_seen = False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip().lstrip("\ufeff")
        if not line:
            continue
        if line.startswith(_COMMENT_PREFIXES):
            match = _UNIT_COMMENT.search(line)
            if match:
                stated.append((match.group(1), number))
            continue
        if width is None:
            delimiter = _detect_delimiter(line)
        tokens = _split(line, delimiter)
        values = [_parse_float(t) for t in tokens]
        if width is None and not rows and not names_seen and all(v is None for v in values):
            names_seen = True
            stated.extend((m.group(1), number) for m in _UNIT_COLUMN.finditer(line))
            continue
        if any(v is None for v in values):
            bad = tokens[[v is None for v in values].index(True)]
            msg = f"{path}:{number}: {bad!r} is not a number"
            raise InputError(msg)
        if width is None:
            width = len(values)
            if width not in columns:
                msg = f"{path}:{number}: rows must have {' or '.join(map(str, columns))} columns, got {width}"
                raise InputError(msg)
        elif len(values) != width:
            msg = f"{path}:{number}: ragged row with {len(values)} columns, earlier rows have {width}"
            raise InputError(msg)
        rows.append([float(v) for v in values if v is not None])
    if width is None or not rows:
        msg = f"{path}: no data rows"
        raise InputError(msg)
    factor = _resolve_unit(path, unit, stated)
    table = np.array(rows, dtype=np.float64)
    nonfinite = ~np.isfinite(table)
    if nonfinite.any():
        row = int(np.argmax(nonfinite.any(axis=1)))
        msg = f"{path}: {int(nonfinite.sum())} NaN/inf values (first in data row {row + 1})"
        raise InputError(msg)
    return table, factor, width


def _resolve_unit(path: Path, unit: str | None, stated: list[tuple[str, int]]) -> float:
    factors = {length_unit_factor(u, what=f"{path}:{line}: unit") for u, line in stated}
    if len(factors) > 1:
        msg = f"{path}: the file states conflicting units {sorted({u for u, _ in stated})}"
        raise InputError(msg)
    if unit is not None:
        given = length_unit_factor(unit)
        if factors and factors != {given}:
            msg = f"{path}: unit {unit!r} was given but the file states {stated[0][0]!r}"
            raise InputError(msg)
        return given
    if not factors:
        msg = f"{path}: no length unit stated (add a '# unit: mm' line or give the unit explicitly)"
        raise InputError(msg)
    return factors.pop()


def read_point_cloud(path: str | Path, *, unit: str | None = None) -> PointCloud:
    """Read a CMM export of one section.

    Parameters
    ----------
    path : str or Path
        Text file of ``x y z`` or ``x y z i j k`` rows; comma, tab, semicolon or blank separated;
        ``#``, ``//``, ``;`` or ``!`` start comment lines; one optional row of column names.
    unit : str, optional
        Length unit of the coordinates (see :data:`LENGTH_UNITS`). Required when the file states
        none; must agree with the file when both are present.

    Returns
    -------
    PointCloud
        Points in metres and, for 6 columns, the unit probe vectors.

    Raises
    ------
    InputError
        Unreadable file, no unit, ragged or non-numeric rows, NaN/inf, zero probe vectors.
    """
    file = Path(path)
    table, factor, width = _read_table(file, unit, (3, 6))
    vectors = table[:, 3:6] if width == 6 else None
    return PointCloud(table[:, :3] * factor, vectors, str(file))


def read_nominal_section(path: str | Path, *, unit: str | None = None) -> NominalSection:
    """Read a nominal contour in the CMM text format (2, 3 or 6 columns, in contour order).

    Parameters
    ----------
    path : str or Path
        Text file as for :func:`read_point_cloud`; only x and y are used.
    unit : str, optional
        Length unit, as for :func:`read_point_cloud`.

    Returns
    -------
    NominalSection
        Counterclockwise contour in metres.
    """
    file = Path(path)
    table, factor, _ = _read_table(file, unit, (2, 3, 6))
    return NominalSection(table[:, :2] * factor, str(file))


def read_rotor37_section(path: str | Path, surface: int, *, scale: float = 1.0) -> NominalSection:
    """One section of the NASA Rotor 37 geometry table, unrolled into the (axial, tangential) plane.

    The table (``J Z R THETA1 THETA2``, Z and R in centimetres, angles in radians) gives 100
    points per surface of revolution; the contour runs through (Z, R·THETA1) for J = 1..100 and
    back through (Z, R·THETA2) for J = 99..2 (J = 1 and 100 are shared by both surfaces).

    Parameters
    ----------
    path : str or Path
        ``nasa_rotor37_blade_geometry.dat``.
    surface : int
        Surface number, 1 (hub) to 13 (shroud).
    scale : float
        Geometric scale factor (dimensionless, > 0) applied after conversion to metres, e.g. to
        bring the blade to the size of the reference paper's (maximum thickness about 30 mm).

    Returns
    -------
    NominalSection
        Counterclockwise contour [m]; x axial (Z), y tangential (R·THETA).
    """
    file = Path(path)
    try:
        lines = file.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        msg = f"cannot read {file}: {err.strerror or err}"
        raise InputError(msg) from err
    if not any("centimeter" in line.lower() for line in lines[:5]):
        msg = f"{file}: not the Rotor 37 table (no 'Z and R are in centimeters' header)"
        raise InputError(msg)
    tables: dict[int, list[list[float]]] = {}
    current: int | None = None
    for line in lines:
        if "SURFACE NUMBER" in line:
            current = int(line.split()[2])
            tables[current] = []
            continue
        tokens = line.split()
        if current is not None and len(tokens) == 5 and tokens[0].isdigit():
            tables[current].append([float(t) for t in tokens])
    if surface not in tables:
        msg = f"{file}: surface must be one of {sorted(tables)}, got {surface!r}"
        raise InputError(msg)
    table = np.array(tables[surface], dtype=np.float64)
    z, r, theta1, theta2 = (table[:, k] * 1.0 for k in range(1, 5))
    first = np.column_stack([z, r * theta1])
    second = np.column_stack([z, r * theta2])[-2:0:-1]
    points = np.concatenate([first, second]) * LENGTH_UNITS["cm"]
    section = NominalSection(points, f"{file.name} surface {surface}")
    return section if scale == 1.0 else section.scaled(scale)


def read_cascade_profile(path: str | Path, *, chord_m: float) -> NominalSection:
    """The DFVLR L030-4 cascade profile (Tecplot zones of chord-normalised x/c, y/c), scaled.

    Parameters
    ----------
    path : str or Path
        ``dfvlr_l030-4_cascade_profile.dat``: an upper and a lower zone, each from the leading
        edge (0, 0) to the trailing edge (1, 0).
    chord_m : float
        Chord length to scale to [m] (> 0).

    Returns
    -------
    NominalSection
        Counterclockwise contour [m].
    """
    if not (math.isfinite(chord_m) and chord_m > 0):
        msg = f"chord_m must be positive and finite, got {chord_m!r}"
        raise InputError(msg)
    file = Path(path)
    try:
        lines = file.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        msg = f"cannot read {file}: {err.strerror or err}"
        raise InputError(msg) from err
    zones: list[list[list[float]]] = []
    for line in lines:
        if line.strip().lower().startswith("zone"):
            zones.append([])
            continue
        values = [_parse_float(t) for t in line.split()]
        if zones and len(values) == 2 and None not in values:
            zones[-1].append([float(v) for v in values if v is not None])
    if len(zones) != 2 or min(len(z) for z in zones) < 3:
        msg = f"{file}: expected two Tecplot zones (upper, lower) of x/c y/c rows, got {len(zones)}"
        raise InputError(msg)
    upper, lower = (np.array(z, dtype=np.float64) for z in zones)
    contour = np.concatenate([upper, lower[-2:0:-1]]) * chord_m
    return NominalSection(contour, f"{file.name} chord {chord_m * 1e3:g} mm")
