"""Cartesian targets for compensation: a CSV with units in its header, or a YAML file.

A target is a position of the measured point (probe, reflector, TCP) and optionally the tool
frame's orientation. Nothing is guessed: lengths and angles name their unit, and Euler
angles name their convention (``roll, pitch, yaw`` mean different rotations in different
tools), so a file that leaves either open is refused in one line.

CSV (comma, semicolon or tab separated; ``#`` lines are comments), header cells
``NAME_UNIT`` or ``NAME [UNIT]``:

- ``x_m, y_m, z_m`` (or ``_mm``, ``_um``): the position; required.
- ``rx_rad, ry_rad, rz_rad`` (or ``_deg``): Euler angles, with the convention given by the
  caller (``--orientation-convention``, one of :data:`~robocal_uncertainty.core.rotation.EULER_CONVENTIONS`);
  or ``qx, qy, qz, qw``: a unit quaternion (no convention needed).

YAML::

    units: {length: mm, angle: deg}
    orientation_convention: extrinsic_xyz     # only with 'euler'
    targets:
      - {position: [500, -200, 300]}
      - {position: [500, -200, 300], euler: [180, 0, 90]}
      - {position: [500, -200, 300], quaternion: [1, 0, 0, 0]}   # x y z w
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from robocal_uncertainty.core.rotation import EULER_CONVENTIONS, euler_to_matrix, quaternion_to_matrix
from robocal_uncertainty.errors import InputError
from robocal_uncertainty.importers.units import canonical_unit, to_si

__all__ = ["Targets", "read_targets"]

Array = NDArray[np.float64]

_CELL = re.compile(r"^\s*([A-Za-z]+)\s*(?:_|\[|\()?\s*([A-Za-zµμ]*)\s*[\])]?\s*$")


@dataclass(frozen=True, eq=False)
class Targets:
    """Targets read from a file, SI units.

    Attributes
    ----------
    points : ndarray, shape (n, 3) [m]
    rotations : ndarray, shape (n, 3, 3), or None
        Tool frame orientations (columns: the tool axes in the target frame); None for
        position-only targets.
    source : str
        The file.
    length_unit, angle_unit : str
        The units the file stated (``angle_unit`` "" without angles).
    orientation : str
        ``"none"``, ``"quaternion"`` or the Euler convention.
    """

    points: Array
    rotations: Array | None
    source: str
    length_unit: str
    angle_unit: str = ""
    orientation: str = "none"

    @property
    def n(self) -> int:
        return int(self.points.shape[0])


def _convention(value: str | None, where: str) -> str:
    if value is None:
        msg = (
            f"{where} gives Euler angles but not their convention (roll/pitch/yaw differ between tools): "
            f"give --orientation-convention, one of {', '.join(EULER_CONVENTIONS)}"
        )
        raise InputError(msg)
    if value not in EULER_CONVENTIONS:
        msg = f"{where}: orientation convention must be one of {', '.join(EULER_CONVENTIONS)}, got {value!r}"
        raise InputError(msg)
    return value


def _header(cells: list[str], where: str) -> dict[str, tuple[int, str]]:
    """Column index and unit of each named column."""
    columns: dict[str, tuple[int, str]] = {}
    for i, cell in enumerate(cells):
        match = _CELL.match(cell)
        if match is None:
            msg = f"{where}: header cell {cell!r} is not NAME_UNIT (e.g. x_mm, rx_deg, qw)"
            raise InputError(msg)
        name, unit = match.group(1).lower(), match.group(2)
        if name in columns:
            msg = f"{where}: column {name!r} is given twice"
            raise InputError(msg)
        columns[name] = (i, unit)
    known = {"x", "y", "z", "rx", "ry", "rz", "qx", "qy", "qz", "qw"}
    unknown = [c for c in columns if c not in known]
    if unknown:
        msg = (
            f"{where}: unknown column {unknown[0]!r}; expected x_UNIT, y_UNIT, z_UNIT (m, mm, um), optionally "
            "rx_UNIT, ry_UNIT, rz_UNIT (rad, deg) or qx, qy, qz, qw"
        )
        raise InputError(msg)
    missing = [c for c in ("x", "y", "z") if c not in columns]
    if missing:
        msg = f"{where}: no column {missing[0]!r} (header {', '.join(cells)}); expected x_m, y_m, z_m or x_mm, ..."
        raise InputError(msg)
    return columns


def _unit(columns: dict[str, tuple[int, str]], names: tuple[str, ...], kind: str, where: str) -> str:
    units = {columns[n][1] for n in names}
    if len(units) != 1:
        msg = f"{where}: columns {', '.join(names)} have different units ({', '.join(sorted(units))})"
        raise InputError(msg)
    stated = units.pop()
    if not stated:
        msg = f"{where}: column {names[0]!r} states no unit: write {names[0]}_{'m' if kind == 'length' else 'rad'}"
        raise InputError(msg)
    unit = canonical_unit(stated, "length" if kind == "length" else "angle")
    if unit is None:
        allowed = "m, mm, um" if kind == "length" else "rad, deg"
        msg = f"{where}: unit {stated!r} of column {names[0]!r} is not one of {allowed}"
        raise InputError(msg)
    return unit


def _read_csv(path: Path, convention: str | None) -> Targets:
    where = f"targets {path}"
    text = path.read_text(encoding="utf-8")
    lines = [
        (k, line)
        for k, line in enumerate(text.splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        msg = f"{where} is empty"
        raise InputError(msg)
    sep = ";" if ";" in lines[0][1] else ("\t" if "\t" in lines[0][1] else ",")
    columns = _header([c.strip() for c in lines[0][1].split(sep)], where)
    length = _unit(columns, ("x", "y", "z"), "length", where)
    euler = [n for n in ("rx", "ry", "rz") if n in columns]
    quat = [n for n in ("qx", "qy", "qz", "qw") if n in columns]
    if euler and quat:
        msg = f"{where}: give Euler angles (rx, ry, rz) or a quaternion (qx, qy, qz, qw), not both"
        raise InputError(msg)
    if (euler and len(euler) != 3) or (quat and len(quat) != 4):
        msg = f"{where}: incomplete orientation columns ({', '.join(euler or quat)})"
        raise InputError(msg)
    angle = _unit(columns, ("rx", "ry", "rz"), "angle", where) if euler else ""
    if euler:
        convention = _convention(convention, where)
    rows: list[list[float]] = []
    for number, line in lines[1:]:
        cells = [c.strip() for c in line.split(sep)]
        if len(cells) != len(columns):
            msg = f"{where}, line {number}: {len(cells)} cells, the header has {len(columns)}"
            raise InputError(msg)
        row = []
        for name, (i, _) in columns.items():
            unit = length if name in ("x", "y", "z") else (angle if name in ("rx", "ry", "rz") else "rad")
            try:
                row.append(to_si(cells[i], unit))
            except ValueError as err:
                msg = f"{where}, line {number}, column {name!r}: {err}"
                raise InputError(msg) from None
        rows.append(row)
    if not rows:
        msg = f"{where} has a header but no target"
        raise InputError(msg)
    values = np.array(rows)
    names = list(columns)

    def col(name: str) -> Array:
        return np.asarray(values[:, names.index(name)], dtype=np.float64)

    points = np.stack([col(n) for n in ("x", "y", "z")], axis=1)
    rotations = None
    orientation = "none"
    if euler:
        assert convention is not None
        rotations = euler_to_matrix(np.stack([col(n) for n in ("rx", "ry", "rz")], axis=1), convention)
        orientation = convention
    elif quat:
        rotations = quaternion_to_matrix(np.stack([col(n) for n in ("qx", "qy", "qz", "qw")], axis=1), name=where)
        orientation = "quaternion"
    return Targets(points, rotations, str(path), length, angle, orientation)


def _numbers(value: Any, size: int, what: str) -> list[str]:
    if not isinstance(value, list) or len(value) != size:
        msg = f"{what} must be a list of {size} numbers, got {value!r}"
        raise InputError(msg)
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            msg = f"{what}: {v!r} is not a number"
            raise InputError(msg)
        out.append(repr(float(v)))
    return out


def _read_yaml(path: Path, convention: str | None) -> Targets:
    where = f"targets {path}"
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as err:
        msg = f"{where} is not valid YAML: {str(err).splitlines()[0]}"
        raise InputError(msg) from None
    if not isinstance(data, dict) or not isinstance(data.get("targets"), list) or not data["targets"]:
        msg = f"{where} has no 'targets' list"
        raise InputError(msg)
    units = data.get("units")
    if not isinstance(units, dict) or "length" not in units:
        msg = f"{where} states no units: add 'units: {{length: m, angle: rad}}'"
        raise InputError(msg)
    length = canonical_unit(str(units["length"]), "length")
    if length is None:
        msg = f"{where}: length unit {units['length']!r} is not one of m, mm, um"
        raise InputError(msg)
    entries = data["targets"]
    kinds = {("euler" in e) * 1 + ("quaternion" in e) * 2 if isinstance(e, dict) else -1 for e in entries}
    if -1 in kinds or 3 in kinds:
        msg = f"{where}: each target is a mapping with 'position' and at most one of 'euler', 'quaternion'"
        raise InputError(msg)
    if len(kinds) != 1:
        msg = f"{where}: some targets give an orientation and some do not; compensate them in separate files"
        raise InputError(msg)
    kind = kinds.pop()
    angle = ""
    if kind == 1:
        angle = canonical_unit(str(units.get("angle", "")), "angle") or ""
        if not angle:
            msg = f"{where}: Euler angles need 'units: {{angle: rad|deg}}', got {units.get('angle')!r}"
            raise InputError(msg)
        given = data.get("orientation_convention")
        if given is not None and convention is not None and given != convention:
            msg = f"{where} says orientation_convention {given!r}, the command line {convention!r}"
            raise InputError(msg)
        convention = _convention(given or convention, where)
    points, angles, quats = [], [], []
    for k, entry in enumerate(entries, start=1):
        what = f"{where}, target {k}"
        try:
            points.append([to_si(v, length) for v in _numbers(entry.get("position"), 3, f"{what}: position")])
            if kind == 1:
                angles.append([to_si(v, angle) for v in _numbers(entry["euler"], 3, f"{what}: euler")])
            elif kind == 2:
                quats.append([float(v) for v in _numbers(entry["quaternion"], 4, f"{what}: quaternion")])
        except ValueError as err:
            msg = f"{what}: {err}"
            raise InputError(msg) from None
    rotations = None
    orientation = "none"
    if kind == 1:
        assert convention is not None
        rotations, orientation = euler_to_matrix(np.array(angles), convention), convention
    elif kind == 2:
        rotations, orientation = quaternion_to_matrix(np.array(quats), name=where), "quaternion"
    return Targets(np.array(points, dtype=np.float64), rotations, str(path), length, angle, orientation)


def read_targets(path: str | Path, *, orientation_convention: str | None = None) -> Targets:
    """Read a targets CSV or YAML file (by suffix: ``.yaml``/``.yml`` or anything else as CSV).

    Raises
    ------
    InputError
        Unreadable file, missing or unknown columns or units, a non-number, NaN or inf, Euler
        angles without a convention; one line naming the file, line and column.
    """
    file = Path(path)
    try:
        if file.suffix.lower() in (".yaml", ".yml"):
            return _read_yaml(file, orientation_convention)
        return _read_csv(file, orientation_convention)
    except OSError as err:
        msg = f"cannot read targets {file}: {err.strerror}"
        raise InputError(msg) from err
    except UnicodeDecodeError as err:
        msg = f"targets {file} is not UTF-8 text (byte {err.start})"
        raise InputError(msg) from err
