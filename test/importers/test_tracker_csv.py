"""Tracker CSV import: the real UR10 laser-tracker file and generic tables with units."""

from __future__ import annotations

from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.errors import CampaignError, InputError
from robocal_uncertainty.importers import read_tracker_csv
from robocal_uncertainty.importers.tracker_csv import IPA_JOINTS

_DATASET = Path("data") / "ur10_laser_tracker"


@pytest.fixture(scope="module")
def ur10_dir() -> Path:
    """The real UR10 dataset: the copy in ``test/data``, else ``shared/data`` above the repo."""
    here = Path(__file__).resolve()
    candidates = [here.parents[1] / _DATASET]
    candidates += [parent / "shared" / _DATASET for parent in here.parents]
    for candidate in candidates:
        if (candidate / "measurements_iso_cubes.csv").is_file():
            return candidate
    pytest.skip("UR10 laser-tracker data not found (test/data or shared/data)")


def _write(tmp_path: Path, text: str, name: str = "table.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# ----------------------------------------------------------------------- real data


def test_real_ur10_file_loads(ur10_dir: Path) -> None:
    campaign = read_tracker_csv(ur10_dir / "measurements_iso_cubes.csv")
    assert campaign.n_poses == 632
    assert campaign.joint_names == IPA_JOINTS
    assert campaign.joint_positions.shape == (632, 6)
    assert (campaign.frame, campaign.frame_id) == ("tracker", "laser_tracker")
    assert campaign.stamps_ns is None
    # first data row: 0,934319;-1,79251;...;2336,7643;0,00095905;-905,76441;...
    assert campaign.joint_positions[0].tolist() == [
        0.934319,
        -1.79251,
        1.5196,
        0.272862,
        0.934269,
        -1.57075,
    ]
    assert campaign.points[0].tolist() == [2.3367643, -0.90576441, -0.45463664]
    assert campaign.point_std is not None
    assert campaign.point_std[0].tolist() == [9.5905e-07, 2.2901e-06, 1.9936e-06]
    assert campaign.metadata["profile"] == "ipa"
    assert campaign.metadata["source_file"] == "measurements_iso_cubes.csv"
    assert campaign.metadata["source_rows"] == list(range(632))
    assert campaign.metadata["skipped_rows"] == []
    assert "Timestamp" in campaign.metadata["ignored_columns"]  # type: ignore[operator]


def test_real_ur10_file_matches_an_independent_parse(ur10_dir: Path) -> None:
    path = ur10_dir / "measurements_iso_cubes.csv"
    lines = path.read_text().splitlines()
    header = lines[0].split(";")
    texts = [[f.replace(",", ".") for f in line.split(";")] for line in lines[1:]]
    table = np.array([[float(f) for f in row] for row in texts])
    # mm -> m is exact: the float nearest to the decimal value of the text shifted by 3 digits
    metres = np.array([[float(Decimal(f).scaleb(-3)) for f in row[13:20]] for row in texts])
    campaign = read_tracker_csv(path, profile="ipa", length_unit="mm", angle_unit="rad")
    joints = [header.index(n) for n in IPA_JOINTS]
    assert np.array_equal(campaign.joint_positions, table[:, joints])
    xyz = [header.index(f"measurement_{a}") for a in "xyz"]
    std = [header.index(f"measurement_std_{a}") for a in "xyz"]
    assert np.array_equal(campaign.points, metres[:, [i - 13 for i in xyz]])
    np.testing.assert_allclose(campaign.points, table[:, xyz] / 1000.0, rtol=3e-16, atol=0)
    assert campaign.point_std is not None
    assert np.array_equal(campaign.point_std, metres[:, [i - 13 for i in std]])


def test_ipa_profile_has_fixed_units(ur10_dir: Path) -> None:
    with pytest.raises(InputError, match="ipa profile has lengths in mm"):
        read_tracker_csv(ur10_dir / "measurements_iso_cubes.csv", length_unit="m")
    with pytest.raises(InputError, match="ipa profile has angles in rad"):
        read_tracker_csv(ur10_dir / "measurements_iso_cubes.csv", angle_unit="deg")


def test_ipa_profile_refuses_other_joint_columns(ur10_dir: Path) -> None:
    """--joint-columns on an ipa file is checked, not silently ignored (wrong names = error)."""
    path = ur10_dir / "measurements_iso_cubes.csv"
    with pytest.raises(InputError, match=r"ipa profile's joint columns are .* got --joint-columns \['a', 'b'\]"):
        read_tracker_csv(path, joint_columns=["a", "b"])
    reordered = list(IPA_JOINTS[::-1])
    with pytest.raises(InputError, match="ipa profile's joint columns"):
        read_tracker_csv(path, joint_columns=reordered)
    assert read_tracker_csv(path, joint_columns=list(IPA_JOINTS)).joint_names == IPA_JOINTS


# --------------------------------------------------------------------- generic tables


def test_generic_deg_and_mm_convert_exactly(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        "Timestamp,joint1[deg],joint2 [deg],x[mm],y[mm],z[mm],std_x[mm],std_y[mm],std_z[mm]\n"
        "17,90,-45.5,2336.7643,-905.76441,0.1,0.00095905,0.002,0.0019936\n"
        "18,0.001,180,1000,1e3,-1,0,0,0\n",
    )
    campaign = read_tracker_csv(path)
    assert campaign.joint_names == ("joint1", "joint2")
    assert campaign.joint_positions.tolist() == [
        [np.deg2rad(90.0), np.deg2rad(-45.5)],
        [np.deg2rad(0.001), np.deg2rad(180.0)],
    ]
    assert campaign.points.tolist() == [[2.3367643, -0.90576441, 0.0001], [1.0, 1.0, -0.001]]
    assert campaign.point_std is not None
    assert campaign.point_std[0].tolist() == [9.5905e-07, 2e-06, 1.9936e-06]
    assert campaign.metadata["profile"] == "generic"
    assert campaign.metadata["units"] == {
        "joint1": "deg",
        "joint2": "deg",
        "x": "mm",
        "y": "mm",
        "z": "mm",
        "std_x": "mm",
        "std_y": "mm",
        "std_z": "mm",
    }
    assert campaign.metadata["ignored_columns"] == ["Timestamp"]
    assert (campaign.frame, campaign.frame_id) == ("tracker", "tracker")


def test_generic_semicolon_decimal_comma_and_unit_arguments(tmp_path: Path) -> None:
    path = _write(tmp_path, "q1;q2;q3;point_x;point_y;point_z\n0,5;-1,25;3;1,5;2;2500,25\n")
    campaign = read_tracker_csv(path, length_unit="µm", angle_unit="rad", frame="base")
    assert campaign.joint_names == ("q1", "q2", "q3")
    assert campaign.joint_positions.tolist() == [[0.5, -1.25, 3.0]]
    assert campaign.points.tolist() == [[1.5e-06, 2e-06, 0.00250025]]
    assert campaign.point_std is None
    assert (campaign.frame, campaign.frame_id) == ("base", "base_link")


def test_generic_joint_columns_choose_and_order_joints(tmp_path: Path) -> None:
    path = _write(tmp_path, "b(rad),a(rad),x(m),y(m),z(m)\n1,2,3,4,5\n")
    campaign = read_tracker_csv(path, joint_columns=["a", "b"])
    assert campaign.joint_names == ("a", "b")
    assert campaign.joint_positions.tolist() == [[2.0, 1.0]]


def test_missing_unit_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x,y[mm],z[mm]\n1,2,3,4\n")
    with pytest.raises(InputError, match="column 'x' has no unit"):
        read_tracker_csv(path)


def test_missing_joint_unit_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1,x[m],y[m],z[m]\n1,2,3,4\n")
    with pytest.raises(InputError, match=r"column 'joint1' has no unit.*--angle-unit"):
        read_tracker_csv(path)


def test_unsupported_unit_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[cm],y[cm],z[cm]\n1,2,3,4\n")
    with pytest.raises(InputError, match="unsupported length unit 'cm'"):
        read_tracker_csv(path)


def test_header_unit_conflicting_with_argument_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[mm],y[mm],z[mm]\n1,2,3,4\n")
    with pytest.raises(InputError, match=r"states unit 'mm' but length unit 'm' was given \(--length-unit\)"):
        read_tracker_csv(path, length_unit="m")


def test_nan_row_raises_naming_the_line(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m]\n1,2,3,4\n1,nan,3,4\n")
    with pytest.raises(InputError, match=r"line 3 \(data row 2\): column 'x'.*not finite"):
        read_tracker_csv(path)


def test_empty_field_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m]\n1,2,,4\n")
    with pytest.raises(InputError, match=r"line 2 .*column 'y' is empty"):
        read_tracker_csv(path)


def test_wrong_field_count_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m]\n1,2,3\n")
    with pytest.raises(InputError, match=r"line 2 .*has 3 fields, the header has 4"):
        read_tracker_csv(path)


def test_skip_invalid_drops_and_counts_rows(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        "joint1[rad],x[m],y[m],z[m],std_x[m],std_y[m],std_z[m]\n"
        "1,2,3,4,0,0,0\n1,nan,3,4,0,0,0\n\n2,,3,4,0,0,0\n3,2,3,4,-1,0,0\n4,5,6,7,0,0,0\n",
    )
    campaign = read_tracker_csv(path, skip_invalid=True)
    assert campaign.joint_positions[:, 0].tolist() == [1.0, 4.0]
    assert campaign.metadata["source_rows"] == [0, 4]
    assert campaign.metadata["skipped_rows"] == [1, 2, 3]


def test_all_rows_invalid_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m]\n1,inf,3,4\n")
    with pytest.raises(InputError, match="no valid data row"):
        read_tracker_csv(path, skip_invalid=True)


def test_missing_point_column_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m]\n1,2,3\n")
    with pytest.raises(InputError, match="point columns must be exactly one each of x, y, z"):
        read_tracker_csv(path)


def test_partial_std_columns_raise(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m],std_x[m]\n1,2,3,4,0\n")
    with pytest.raises(InputError, match="std columns must be exactly one each"):
        read_tracker_csv(path)


def test_no_joint_column_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "angle[rad],x[m],y[m],z[m]\n1,2,3,4\n")
    with pytest.raises(InputError, match="no joint column found"):
        read_tracker_csv(path)


def test_forcing_ipa_on_another_layout_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m]\n1,2,3,4\n")
    with pytest.raises(InputError, match="not in the ipa format"):
        read_tracker_csv(path, profile="ipa")


def test_unknown_profile_raises(tmp_path: Path) -> None:
    path = _write(tmp_path, "joint1[rad],x[m],y[m],z[m]\n1,2,3,4\n")
    with pytest.raises(InputError, match="unknown tracker CSV profile 'leica'"):
        read_tracker_csv(path, profile="leica")  # type: ignore[arg-type]


def test_missing_file_raises(tmp_path: Path) -> None:
    with pytest.raises(CampaignError, match="tracker CSV file not found"):
        read_tracker_csv(tmp_path / "nope.csv")


def test_empty_file_raises(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="is empty"):
        read_tracker_csv(_write(tmp_path, "\n\n"))
