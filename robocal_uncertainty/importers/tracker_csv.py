"""Import a laser-tracker measurement table (CSV) as a :class:`Campaign`.

Profiles
--------
``ipa``
    The "ipa-robot-accuracy" UR10 dataset (Landgraf et al. 2021): semicolon separator,
    decimal comma, joint columns ``shoulder_pan_joint`` ... ``wrist_3_joint`` in rad,
    ``measurement_x/y/z`` and ``measurement_std_x/y/z`` in mm, points in the tracker frame
    (``frame="tracker"``, ``frame_id="laser_tracker"``). Its ``Timestamp`` column is mangled
    by a spreadsheet (``2,02103E+13``) and is not used.
``generic``
    Comma-, semicolon- or tab-separated (semicolon or tab: a comma inside a number is a
    decimal comma),
    one header row. Units are written in the header, ``name[unit]`` or ``name(unit)``, or
    given by `length_unit` / `angle_unit`; a column with no unit anywhere is an error.
    Columns: ``x``, ``y``, ``z`` (optionally prefixed ``point_``/``measurement_``) for the
    point; ``std_x`` or ``x_std`` (same prefixes) for its standard deviation; joint columns
    are those named in `joint_columns`, else every column whose name contains ``joint`` or
    is ``q<digits>``, in file order. Other columns are ignored (listed in the metadata).
``auto`` (default)
    ``ipa`` when the header has all its joint and measurement columns, else ``generic``.

Orientation (6-DOF probes)
--------------------------
With `orientation_columns` (three names, the Euler angles in the order of the convention) the
campaign is a 6-DOF campaign (:class:`~robocal_uncertainty.core.pose_measurement.PoseMeasurement`).
Their unit is the header's or `orientation_unit`, their convention `orientation_convention`
(one of :data:`~robocal_uncertainty.core.rotation.EULER_CONVENTIONS`): neither has a default for
the ``generic`` profile, a missing one is an error. The ``ipa`` profile reads
``measurement_rx/ry/rz`` in degrees, intrinsic XYZ (``Rx(rx) Ry(ry) Rz(rz)``; established
against the UR10 kinematics in ``test/importers/test_ur10_orientation_convention.py``); a
different stated unit or convention is an error. Standard deviation columns of the angles
(``<prefix>std_<name>``, ``std_<name>`` or ``<name>_std``; ``measurement_std_rx`` ... for
``ipa``) are propagated to standard deviations of the rotation about the tracker frame's fixed
x, y, z axes (the residual's components) through the Euler angles' Jacobian, uncorrelated
angles assumed. The measurement's weights are the median over the poses of each axis'
standard deviation (position and rotation), so position and orientation residuals count in
units of their typical instrument uncertainty.

Units: lengths m, mm, um (also µm); angles rad, deg. Lengths are converted exactly from
their decimal text (see :mod:`~robocal_uncertainty.importers.units`).

Metadata of the campaign: ``source_file``, ``source_format`` ("csv"), ``profile``,
``source_rows`` (0-based index of every kept pose among the non-blank rows after the
header, as ``pandas.read_csv`` numbers them), ``skipped_rows`` (same numbering), ``units``
(per column used) and ``ignored_columns``. Error messages name the file line and the data
row counted from 1 (the first row after the header).
"""

from __future__ import annotations

import csv
import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from robocal_uncertainty.core.campaign import Campaign, PointFrame
from robocal_uncertainty.core.measurement import POINT, MeasurementType
from robocal_uncertainty.core.pose_measurement import PoseMeasurement, pose_values
from robocal_uncertainty.core.rotation import EULER_CONVENTIONS, euler_to_matrix, rotation_log
from robocal_uncertainty.errors import CampaignError, InputError
from robocal_uncertainty.importers.units import (
    ANGLE_UNITS,
    LENGTH_UNITS,
    UnitKind,
    canonical_unit,
    to_si,
)

__all__ = ["IPA_JOINTS", "IPA_ORIENTATION", "Profile", "read_tracker_csv"]

Profile = Literal["auto", "ipa", "generic"]

IPA_JOINTS: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
_IPA_POINT = ("measurement_x", "measurement_y", "measurement_z")
_IPA_STD = ("measurement_std_x", "measurement_std_y", "measurement_std_z")
_IPA_FRAME_ID = "laser_tracker"
IPA_ORIENTATION: tuple[str, str, str] = ("measurement_rx", "measurement_ry", "measurement_rz")
"""The ipa series' orientation columns: degrees, intrinsic XYZ Euler angles."""
_IPA_ORIENTATION_UNIT = "deg"
_IPA_CONVENTION = "intrinsic_xyz"

_HEADER_CELL = re.compile(r"^\s*(?P<name>[^\[\(]*?)\s*(?:[\[\(]\s*(?P<unit>[^\]\)]*?)\s*[\]\)])?\s*$")
_PREFIX = r"(?:(?:point|measurement|meas|tracker)_)?"
_POINT_NAME = re.compile(rf"^{_PREFIX}(?P<axis>[xyz])$", re.IGNORECASE)
_STD_NAME = re.compile(rf"^{_PREFIX}(?:std_(?P<a>[xyz])|(?P<b>[xyz])_std)$", re.IGNORECASE)
_JOINT_NAME = re.compile(r"^(?:q\d+|.*joint.*)$", re.IGNORECASE)


@dataclass(frozen=True)
class _Column:
    """A used column: its index, role (joint/point/std), axis or joint name, and unit."""

    index: int
    name: str
    role: Literal["joint", "point", "std", "angle", "angle_std"]
    key: str
    unit: str


def _split_header(cell: str) -> tuple[str, str | None]:
    match = _HEADER_CELL.match(cell)
    if match is None:
        return cell.strip(), None
    unit = match.group("unit")
    return match.group("name"), (unit if unit else None)


def _resolve_unit(
    path: Path, name: str, stated: str | None, given: str | None, kind: UnitKind, *, option: str | None = None
) -> str:
    supported = ", ".join(LENGTH_UNITS if kind == "length" else ANGLE_UNITS)
    option = option or f"{kind}-unit"
    argument = f"the {kind} unit (import-csv --{option})"
    if stated is None and given is None:
        msg = (
            f"{path}: column {name!r} has no unit; write it in the header as "
            f"'{name}[unit]' or give {argument} (supported: {supported})"
        )
        raise InputError(msg)
    units = [canonical_unit(u, kind) for u in (stated, given) if u is not None]
    if None in units:
        bad = stated if stated is not None and canonical_unit(stated, kind) is None else given
        msg = f"{path}: column {name!r} has unsupported {kind} unit {bad!r} (supported: {supported})"
        raise InputError(msg)
    if len(set(units)) > 1:
        msg = f"{path}: column {name!r} states unit {stated!r} but {kind} unit {given!r} was given (--{option})"
        raise InputError(msg)
    return str(units[0])


def _ipa_columns(path: Path, header: list[str], length_unit: str | None, angle_unit: str | None) -> list[_Column]:
    checks: tuple[tuple[str | None, str, UnitKind], ...] = (
        (length_unit, "mm", "length"),
        (angle_unit, "rad", "angle"),
    )
    for given, fixed, kind in checks:
        if given is not None and canonical_unit(given, kind) != fixed:
            msg = f"{path}: the ipa profile has {kind}s in {fixed}, got --{kind}-unit {given}"
            raise InputError(msg)
    position = {cell.strip(): i for i, cell in enumerate(header)}
    missing = [n for n in IPA_JOINTS + _IPA_POINT + _IPA_STD if n not in position]
    if missing:
        msg = f"{path}: not in the ipa format, columns {missing} are missing"
        raise InputError(msg)
    columns = [_Column(position[n], n, "joint", n, "rad") for n in IPA_JOINTS]
    columns += [_Column(position[n], n, "point", n[-1], "mm") for n in _IPA_POINT]
    columns += [_Column(position[n], n, "std", n[-1], "mm") for n in _IPA_STD]
    return columns


def _generic_columns(
    path: Path,
    header: list[str],
    length_unit: str | None,
    angle_unit: str | None,
    joint_columns: tuple[str, ...] | None,
) -> tuple[list[_Column], list[str]]:
    columns: list[_Column] = []
    ignored: list[str] = []
    for index, cell in enumerate(header):
        name, stated = _split_header(cell)
        point, std = _POINT_NAME.match(name), _STD_NAME.match(name)
        is_joint = name in joint_columns if joint_columns is not None else bool(_JOINT_NAME.match(name))
        if is_joint:
            unit = _resolve_unit(path, name, stated, angle_unit, "angle")
            columns.append(_Column(index, name, "joint", name, unit))
        elif point is not None:
            unit = _resolve_unit(path, name, stated, length_unit, "length")
            columns.append(_Column(index, name, "point", point.group("axis").lower(), unit))
        elif std is not None:
            unit = _resolve_unit(path, name, stated, length_unit, "length")
            axis = (std.group("a") or std.group("b")).lower()
            columns.append(_Column(index, name, "std", axis, unit))
        else:
            ignored.append(cell.strip())
    joints = [c for c in columns if c.role == "joint"]
    if joint_columns is not None and len(joints) != len(joint_columns):
        found = {c.name for c in joints}
        absent = [n for n in joint_columns if n not in found]
        msg = f"{path}: joint columns {absent} not in the header"
        raise InputError(msg)
    if not joints:
        msg = (
            f"{path}: no joint column found (names containing 'joint' or q1, q2, ...; "
            "or name them with import-csv --joint-columns)"
        )
        raise InputError(msg)
    for role, needed in (("point", True), ("std", False)):
        axes = sorted(c.key for c in columns if c.role == role)
        if axes != ["x", "y", "z"] and (needed or axes):
            msg = f"{path}: {role} columns must be exactly one each of x, y, z, found {axes}"
            raise InputError(msg)
    names = [c.name for c in joints]
    if len(set(names)) != len(names):
        msg = f"{path}: joint column names repeat: {names}"
        raise InputError(msg)
    return columns, ignored


def _orientation_columns(
    path: Path,
    header: list[str],
    names: tuple[str, ...],
    unit: str | None,
    fixed_unit: str | None,
) -> list[_Column]:
    """The three angle columns and, when all present, their std columns."""
    if len(names) != 3 or len(set(names)) != 3:
        msg = f"{path}: orientation columns must be three distinct names, got {list(names)}"
        raise InputError(msg)
    if fixed_unit is not None and unit is not None and canonical_unit(unit, "angle") != fixed_unit:
        msg = f"{path}: the ipa profile has orientations in {fixed_unit}, got --orientation-unit {unit}"
        raise InputError(msg)
    given = fixed_unit or unit
    cells = {_split_header(cell)[0]: (i, _split_header(cell)[1]) for i, cell in enumerate(header)}
    out: list[_Column] = []
    for k, name in enumerate(names):
        if name not in cells:
            msg = f"{path}: orientation column {name!r} not in the header"
            raise InputError(msg)
        index, stated = cells[name]
        angle_unit = _resolve_unit(path, name, stated, given, "angle", option="orientation-unit")
        out.append(_Column(index, name, "angle", "xyz"[k], angle_unit))
    stds: list[_Column] = []
    for k, name in enumerate(names):
        prefix, _, short = name.rpartition("_")
        candidates = [f"{prefix}_std_{short}" if prefix else f"std_{short}", f"std_{name}", f"{name}_std"]
        found = [c for c in candidates if c in cells]
        if found:
            index, stated = cells[found[0]]
            std_unit = _resolve_unit(path, found[0], stated, given, "angle", option="orientation-unit")
            stds.append(_Column(index, found[0], "angle_std", "xyz"[k], std_unit))
    if stds and len(stds) != 3:
        msg = f"{path}: orientation std columns must be given for all three angles, found {[c.name for c in stds]}"
        raise InputError(msg)
    return out + stds


def _rotation_std(angles: np.ndarray, angle_std: np.ndarray, convention: str) -> np.ndarray:
    """Std [rad] of the rotation about the fixed x, y, z axes from uncorrelated Euler-angle stds.

    ``Sigma = J diag(s^2) J^T`` with ``J[:, k] = d log(R(a) R(a0)^T) / d a_k`` (central
    differences, step 1e-6 rad); returns ``sqrt(diag(Sigma))``, shape (n, 3).
    """
    h = 1e-6
    base = euler_to_matrix(angles, convention)
    jac = np.empty((angles.shape[0], 3, 3))
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        plus = rotation_log(euler_to_matrix(angles + step, convention) @ np.swapaxes(base, -1, -2))
        minus = rotation_log(euler_to_matrix(angles - step, convention) @ np.swapaxes(base, -1, -2))
        jac[:, :, k] = (plus - minus) / (2 * h)
    cov = jac @ (angle_std[:, :, None] ** 2 * np.swapaxes(jac, -1, -2))
    return np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))


def _read_rows(path: Path) -> tuple[str, list[list[str]], list[int]]:
    """Return the separator, the rows (header first) and each row's line number."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError as err:
        msg = f"tracker CSV file not found: {path}"
        raise CampaignError(msg) from err
    except (OSError, UnicodeDecodeError) as err:
        msg = f"cannot read tracker CSV {path}: {err}"
        raise CampaignError(msg) from err
    first = next((line for line in text.splitlines() if line.strip()), "")
    if not first:
        msg = f"tracker CSV {path} is empty"
        raise InputError(msg)
    # Spreadsheets export tab-separated text as "CSV" too; a comma in a number is then a
    # decimal comma, as with semicolons.
    separator = "\t" if "\t" in first else ";" if ";" in first else ","
    reader = csv.reader(text.splitlines(), delimiter=separator)
    rows, lines = [], []
    for row in reader:
        if any(field.strip() for field in row):
            rows.append(row)
            lines.append(reader.line_num)
    return separator, rows, lines


@dataclass(frozen=True)
class _Layout:
    """What the header says: the profile, the used columns and the frame of the points."""

    profile: Profile
    columns: list[_Column]
    ignored: list[str]
    frame: PointFrame
    frame_id: str


def _position_layout(
    path: Path,
    header: list[str],
    profile: Profile,
    *,
    length_unit: str | None,
    angle_unit: str | None,
    joint_columns: tuple[str, ...] | list[str] | None,
    frame: PointFrame | None,
    frame_id: str | None,
) -> _Layout:
    """Joint, point and std columns of the file's profile (``auto`` resolved from the header)."""
    cells = {cell.strip() for cell in header}
    if profile == "auto":
        profile = "ipa" if set(IPA_JOINTS + _IPA_POINT + _IPA_STD) <= cells else "generic"
    if profile == "ipa":
        if joint_columns is not None and tuple(joint_columns) != IPA_JOINTS:
            msg = (
                f"{path}: the ipa profile's joint columns are {list(IPA_JOINTS)}, "
                f"got --joint-columns {list(joint_columns)}"
            )
            raise InputError(msg)
        columns = _ipa_columns(path, header, length_unit, angle_unit)
        used = {c.index for c in columns}
        ignored = [cell.strip() for i, cell in enumerate(header) if i not in used]
        if (frame or "tracker") != "tracker" or (frame_id or _IPA_FRAME_ID) != _IPA_FRAME_ID:
            msg = f"{path}: the ipa profile is in frame 'tracker'/{_IPA_FRAME_ID!r}, got {frame!r}/{frame_id!r}"
            raise InputError(msg)
        return _Layout(profile, columns, ignored, "tracker", _IPA_FRAME_ID)
    names = None if joint_columns is None else tuple(joint_columns)
    columns, ignored = _generic_columns(path, header, length_unit, angle_unit, names)
    if names is not None:
        order = {n: i for i, n in enumerate(names)}
        columns.sort(key=lambda c: (c.role != "joint", order.get(c.name, 0)))
    frame = frame or "tracker"
    frame_id = frame_id or ("base_link" if frame == "base" else "tracker")
    return _Layout(profile, columns, ignored, frame, frame_id)


def _orientation_convention(path: Path, profile: Profile, names: tuple[str, ...], convention: str | None) -> str:
    """The Euler convention of the angle columns: the ipa profile's fixed one or the stated one."""
    if profile == "ipa":
        if names != IPA_ORIENTATION:
            msg = f"{path}: the ipa profile's orientation columns are {list(IPA_ORIENTATION)}, got {list(names)}"
            raise InputError(msg)
        if convention not in (None, _IPA_CONVENTION):
            msg = (
                f"{path}: the ipa profile's orientations are {_IPA_CONVENTION} Euler angles, "
                f"got --orientation-convention {convention}"
            )
            raise InputError(msg)
        convention = _IPA_CONVENTION
    elif convention is None:
        msg = (
            f"{path}: orientation columns need their Euler convention "
            f"(import-csv --orientation-convention: {', '.join(EULER_CONVENTIONS)})"
        )
        raise InputError(msg)
    if convention not in EULER_CONVENTIONS:
        msg = f"{path}: unknown orientation convention {convention!r} (supported: {', '.join(EULER_CONVENTIONS)})"
        raise InputError(msg)
    return convention


def _with_orientation(
    path: Path,
    header: list[str],
    layout: _Layout,
    orientation_columns: tuple[str, ...] | list[str] | None,
    *,
    unit: str | None,
    convention: str | None,
) -> tuple[_Layout, str | None]:
    """`layout` with the angle (and angle std) columns added, and their Euler convention.

    Unchanged, and no convention, when the call asks for no orientation (the ipa profile reads
    its fixed angle columns when a unit or convention is given for them).
    """
    wants_orientation = orientation_columns is not None or (
        layout.profile == "ipa" and (unit is not None or convention is not None)
    )
    if not wants_orientation:
        return layout, None
    names = tuple(orientation_columns) if orientation_columns is not None else IPA_ORIENTATION
    convention = _orientation_convention(path, layout.profile, names, convention)
    fixed = _IPA_ORIENTATION_UNIT if layout.profile == "ipa" else None
    o_columns = _orientation_columns(path, header, names, unit, fixed)
    o_indices = {c.index for c in o_columns}
    ignored = [name for name in layout.ignored if name not in {c.name for c in o_columns}]
    columns = [c for c in layout.columns if c.index not in o_indices] + o_columns
    return dataclasses.replace(layout, columns=columns, ignored=ignored), convention


@dataclass(frozen=True)
class _Rows:
    """The values of the valid data rows, by role, SI units."""

    joints: list[list[float]]
    points: list[list[float]]
    std: list[list[float]]
    angles: list[list[float]]
    angle_std: list[list[float]]
    kept: list[int]
    skipped: list[int]
    has_std: bool
    has_angle_std: bool


def _collect_rows(
    path: Path,
    rows: list[list[str]],
    lines: list[int],
    columns: list[_Column],
    separator: str,
    *,
    skip_invalid: bool,
) -> _Rows:
    """Parse every data row; a bad one raises (naming its line) or is skipped."""
    header = rows[0]
    joints = [c for c in columns if c.role == "joint"]
    axes = {c.role + c.key: c for c in columns if c.role != "joint"}
    has_std = "stdx" in axes
    has_angle_std = "angle_stdx" in axes
    wants_orientation = "anglex" in axes
    out = _Rows([], [], [], [], [], [], [], has_std, has_angle_std)
    for data_row, (row, line) in enumerate(zip(rows[1:], lines[1:], strict=True)):
        try:
            values = _parse_row(row, header, columns, separator)
        except ValueError as err:
            if not skip_invalid:
                msg = f"{path}: line {line} (data row {data_row + 1}): {err}"
                raise InputError(msg) from None
            out.skipped.append(data_row)
            continue
        out.joints.append([values[c.index] for c in joints])
        out.points.append([values[axes["point" + a].index] for a in "xyz"])
        if has_std:
            out.std.append([values[axes["std" + a].index] for a in "xyz"])
        if wants_orientation:
            out.angles.append([values[axes["angle" + a].index] for a in "xyz"])
            if has_angle_std:
                out.angle_std.append([values[axes["angle_std" + a].index] for a in "xyz"])
        out.kept.append(data_row)
    if not out.kept:
        msg = f"{path}: no valid data row ({len(out.skipped)} skipped)"
        raise InputError(msg)
    return out


def _pose_campaign_values(
    path: Path, rows: _Rows, points: np.ndarray, point_std: np.ndarray | None, convention: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, PoseMeasurement]:
    """Pose values, their std (position and rotation), its median per axis and the measurement it weighs."""
    angles = np.array(rows.angles, dtype=np.float64)
    points = pose_values(points, euler_to_matrix(angles, convention))
    if point_std is None or not rows.has_angle_std:
        msg = (
            f"{path}: a 6-DOF campaign needs the standard deviations of the position and of the "
            "orientation (std columns) to weigh the two kinds of residual"
        )
        raise InputError(msg)
    rot_std = _rotation_std(angles, np.array(rows.angle_std, dtype=np.float64), convention)
    point_std = np.concatenate((point_std, rot_std), axis=1)
    median = np.median(point_std, axis=0)
    if not (median > 0).all():
        msg = f"{path}: the median standard deviation of each axis must be positive, got {median.tolist()}"
        raise InputError(msg)
    measurement = PoseMeasurement(
        (float(median[0]), float(median[1]), float(median[2])),
        (float(median[3]), float(median[4]), float(median[5])),
    )
    return points, point_std, median, measurement


def _campaign(path: Path, layout: _Layout, data: _Rows, orientation_convention: str | None) -> Campaign:
    """The campaign of the parsed rows, points only or poses (with an orientation convention)."""
    columns = layout.columns
    metadata: dict[str, object] = {
        "source_file": path.name,
        "source_format": "csv",
        "profile": layout.profile,
        "source_rows": data.kept,
        "skipped_rows": data.skipped,
        "units": {c.name: c.unit for c in columns},
        "ignored_columns": layout.ignored,
    }
    points = np.array(data.points, dtype=np.float64)
    point_std = np.array(data.std, dtype=np.float64) if data.has_std else None
    measurement: MeasurementType = POINT
    if orientation_convention is not None:
        metadata["orientation_convention"] = orientation_convention
        points, point_std, median, measurement = _pose_campaign_values(
            path, data, points, point_std, orientation_convention
        )
        metadata["weights_std"] = {"position_m": median[:3].tolist(), "rotation_rad": median[3:].tolist()}
    return Campaign(
        joint_names=tuple(c.name for c in columns if c.role == "joint"),
        joint_positions=np.array(data.joints, dtype=np.float64),
        points=points,
        frame=layout.frame,
        frame_id=layout.frame_id,
        point_std=point_std,
        metadata=metadata,
        measurement=measurement,
    )


def read_tracker_csv(
    path: str | Path,
    *,
    profile: Profile = "auto",
    length_unit: str | None = None,
    angle_unit: str | None = None,
    skip_invalid: bool = False,
    joint_columns: tuple[str, ...] | list[str] | None = None,
    frame: PointFrame | None = None,
    frame_id: str | None = None,
    orientation_columns: tuple[str, ...] | list[str] | None = None,
    orientation_unit: str | None = None,
    orientation_convention: str | None = None,
) -> Campaign:
    """Read a tracker CSV into a campaign with joint positions [rad] and points [m].

    Parameters
    ----------
    path : str or Path
        The CSV file.
    profile : {"auto", "ipa", "generic"}
        File layout (see the module documentation).
    length_unit, angle_unit : str, optional
        Units of columns whose header states none (``generic``), or a check of the fixed
        units (``ipa``: mm and rad). A header unit different from the argument is an error.
    skip_invalid : bool
        Drop rows with empty, non-numeric, NaN/inf or negative-std values, or a wrong field
        count (listed in ``metadata["skipped_rows"]``) instead of raising.
    joint_columns : sequence of str, optional
        ``generic``: names (without unit) of the joint columns, in the wanted order;
        ``ipa``: must be :data:`IPA_JOINTS` (anything else is an error, never ignored).
    frame, frame_id : optional
        Frame of the points; ``ipa``: ``"tracker"``/``"laser_tracker"`` (fixed);
        ``generic``: default ``"tracker"`` and ``"tracker"`` (``"base_link"`` for base).
    orientation_columns : sequence of 3 str, optional
        Euler-angle columns of a 6-DOF probe (see the module documentation); ``ipa``: must
        be :data:`IPA_ORIENTATION` (or pass ``orientation_convention``/``orientation_unit``
        alone to read them). None: points only.
    orientation_unit : {"rad", "deg"}, optional
        Unit of the angle columns whose header states none.
    orientation_convention : str, optional
        Euler convention of the angles; required with generic orientation columns.

    Returns
    -------
    Campaign
        joint_positions (n, n_joints) [rad], points (n, 3) [m], point_std (n, 3) [m] when the
        file has std columns, no stamps.

    Raises
    ------
    CampaignError
        The file is missing or unreadable.
    InputError
        Unknown profile, missing columns, a column without (or with an unsupported) unit, or
        an invalid row (unless `skip_invalid`).
    """
    path = Path(path)
    if profile not in ("auto", "ipa", "generic"):
        msg = f"unknown tracker CSV profile {profile!r} (expected 'auto', 'ipa' or 'generic')"
        raise InputError(msg)
    separator, rows, lines = _read_rows(path)
    header = rows[0]
    layout = _position_layout(
        path,
        header,
        profile,
        length_unit=length_unit,
        angle_unit=angle_unit,
        joint_columns=joint_columns,
        frame=frame,
        frame_id=frame_id,
    )
    layout, convention = _with_orientation(
        path, header, layout, orientation_columns, unit=orientation_unit, convention=orientation_convention
    )
    data = _collect_rows(path, rows, lines, layout.columns, separator, skip_invalid=skip_invalid)
    return _campaign(path, layout, data, convention)


MAX_COORDINATE_M = 1000.0
"""Largest |coordinate| [m] accepted from a tracker CSV (laser trackers reach tens of metres)."""


def _parse_row(row: list[str], header: list[str], columns: list[_Column], separator: str) -> dict[int, float]:
    """Return SI values by column index; ValueError names the bad column."""
    while len(row) > len(header) and not row[-1].strip():
        row = row[:-1]
    if len(row) != len(header):
        msg = f"has {len(row)} fields, the header has {len(header)}"
        raise ValueError(msg)
    values: dict[int, float] = {}
    for column in columns:
        text = row[column.index].strip()
        if separator in (";", "\t"):
            text = text.replace(",", ".")
        if not text:
            msg = f"column {column.name!r} is empty"
            raise ValueError(msg)
        try:
            value = to_si(text, column.unit)
        except ValueError as err:
            msg = f"column {column.name!r}: {err}"
            raise ValueError(msg) from None
        if column.role in ("std", "angle_std") and value < 0:
            msg = f"column {column.name!r}: negative standard deviation {text!r}"
            raise ValueError(msg)
        if column.role == "point" and abs(value) > MAX_COORDINATE_M:
            # No tracker measures that far; a number this size is a corrupt cell or a unit slip,
            # and squared in the fit it overflows.
            msg = (
                f"column {column.name!r}: {text!r} is a coordinate of {value:.3g} m, farther than any tracker "
                f"measures ({MAX_COORDINATE_M:g} m): a corrupt value or a wrong unit"
            )
            raise ValueError(msg)
        values[column.index] = value
    return values
