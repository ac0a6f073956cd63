"""Reading CMM exports and nominal sections: formats, units, one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from inspection_data import CASCADE, ROTOR37

from robocal_uncertainty.errors import InputError
from robocal_uncertainty.inspection.point_cloud import (
    NominalSection,
    PointCloud,
    read_cascade_profile,
    read_nominal_section,
    read_point_cloud,
    read_rotor37_section,
)


def write(tmp_path: Path, text: str, name: str = "cloud.txt") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    "body",
    [
        "# unit: mm\n1 2 3\n4 5 6\n",
        "# unit: mm\n1\t2\t3\n4\t5\t6\n",
        "# units = mm\n1,2,3\n4, 5, 6\n",
        "x[mm];y[mm];z[mm]\n1;2;3\n4;5;6\n",
        "// UNIT: MM\n  1   2   3\n\n4 5 6\n",
    ],
)
def test_formats_and_stated_units(tmp_path: Path, body: str) -> None:
    cloud = read_point_cloud(write(tmp_path, body))
    assert cloud.points == pytest.approx(np.array([[1, 2, 3], [4, 5, 6]]) * 1e-3)
    assert cloud.probe_vectors is None
    assert cloud.n_points == 2 and cloud.xy.shape == (2, 2)


def test_explicit_unit_and_probe_vectors(tmp_path: Path) -> None:
    path = write(tmp_path, "x,y,z,i,j,k\n1,2,3,0,0,2\n4,5,6,3,4,0\n")
    cloud = read_point_cloud(path, unit="cm")
    assert cloud.points[1] == pytest.approx([0.04, 0.05, 0.06])
    assert cloud.probe_vectors is not None
    assert cloud.probe_vectors == pytest.approx(np.array([[0, 0, 1], [0.6, 0.8, 0]]))
    assert cloud.source == str(path)


@pytest.mark.parametrize(
    ("body", "unit", "match"),
    [
        ("1 2 3\n", None, "no length unit stated"),
        ("# unit: mm\n1 2 3\n", "m", "unit 'm' was given but the file states 'mm'"),
        ("# unit: mm\n# unit: m\n1 2 3\n", None, "conflicting units"),
        ("# unit: furlong\n1 2 3\n", None, "unit must be one of"),
        ("1 2 3\n", "parsec", "unit must be one of"),
        ("# unit: mm\n1 2 3\n4 5\n", None, r"cloud.txt:3: ragged row with 2 columns, earlier rows have 3"),
        ("# unit: mm\n1 2 3 4\n", None, "rows must have 3 or 6 columns, got 4"),
        ("# unit: mm\n1 2 3\n4 x 6\n", None, r"cloud.txt:3: 'x' is not a number"),
        ("# unit: mm\n1 2 3\nnan 5 6\n", None, r"1 NaN/inf values \(first in data row 2\)"),
        ("# unit: mm\n", None, "no data rows"),
        ("", "mm", "no data rows"),
        ("# unit: mm\n1 2 3 0 0 0\n", None, "probe vector of point 0 has zero length"),
    ],
)
def test_careless_files_end_in_one_line_errors(tmp_path: Path, body: str, unit: str | None, match: str) -> None:
    with pytest.raises(InputError, match=match) as info:
        read_point_cloud(write(tmp_path, body), unit=unit)
    assert "\n" not in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read"):
        read_point_cloud(tmp_path / "absent.txt", unit="mm")


def test_point_cloud_validates_arrays_from_any_reader() -> None:
    with pytest.raises(InputError, match=r"shape \(n, 3\)"):
        PointCloud(np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"bag: points contain 1 NaN/inf values \(first in point 2\)"):
        PointCloud(np.array([[0, 0, 0], [1, 0, 0], [np.inf, 0, 0]]), source="bag")
    with pytest.raises(InputError, match=r"probe_vectors must have shape \(1, 3\)"):
        PointCloud(np.zeros((1, 3)), np.zeros((2, 3)))
    cloud = PointCloud(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="read-only"):
        cloud.points[0, 0] = 1.0


def test_nominal_section_text_file_is_reordered_counterclockwise(tmp_path: Path) -> None:
    t = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    clockwise = np.column_stack([10 * np.cos(-t), 2 * np.sin(-t)])
    text = "# unit: mm\n" + "\n".join(f"{x} {y}" for x, y in clockwise) + "\n"
    section = read_nominal_section(write(tmp_path, text, "nominal.txt"))
    x, y = section.points[:, 0], section.points[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
    assert section.points[0] == pytest.approx([0.01, 0.0])
    assert section.n_points == 24


def test_nominal_section_refusals() -> None:
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0.5], [0.2, 0.2], [0.1, 0.1], [0, 0.05]], float)
    NominalSection(square)
    with pytest.raises(InputError, match="at least 8 contour points"):
        NominalSection(square[:5])
    bow_tie = np.array([[0, 0], [1, 1], [2, 1], [3, 0], [3, 1], [2, 0], [1, 0], [0, 1]], float)
    with pytest.raises(InputError, match="intersects itself"):
        NominalSection(bow_tie, "bow tie")
    repeated = np.concatenate([square[:3], square[2:]])
    with pytest.raises(InputError, match="repeats its successor"):
        NominalSection(repeated)
    closed = np.concatenate([square, square[:1]])
    assert NominalSection(closed).n_points == 8
    with pytest.raises(InputError, match="scale factor"):
        NominalSection(square).scaled(-1.0)


def test_rotor37_sections() -> None:
    section = read_rotor37_section(ROTOR37, 2)
    assert section.n_points == 198
    assert np.ptp(section.points[:, 0]) == pytest.approx(0.04177, abs=1e-5)  # axial extent [m]
    scaled = read_rotor37_section(ROTOR37, 2, scale=2.0)
    assert np.allclose(scaled.points, 2.0 * section.points)
    with pytest.raises(InputError, match="surface must be one of"):
        read_rotor37_section(ROTOR37, 14)
    with pytest.raises(InputError, match="not the Rotor 37 table"):
        read_rotor37_section(CASCADE, 1)


def test_cascade_profile() -> None:
    section = read_cascade_profile(CASCADE, chord_m=0.2)
    assert section.n_points == 92
    assert np.ptp(section.points[:, 0]) == pytest.approx(0.2, abs=1e-12)
    with pytest.raises(InputError, match="chord_m"):
        read_cascade_profile(CASCADE, chord_m=0.0)
    with pytest.raises(InputError, match="two Tecplot zones"):
        read_cascade_profile(ROTOR37, chord_m=0.2)
