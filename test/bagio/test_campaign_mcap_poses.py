"""6-DOF campaigns in the campaign MCAP: PoseStamped beside /tracker/point, the orientation
std, the measurement record; point campaigns and old files unchanged; bad quaternions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robocal_uncertainty.bagio import read_campaign, write_campaign
from robocal_uncertainty.bagio.campaign_mcap import CampaignRecorder
from robocal_uncertainty.cli import main
from robocal_uncertainty.core.pose_measurement import PoseMeasurement
from robocal_uncertainty.core.robot_formats.robot_yaml import load_robot_model
from robocal_uncertainty.core.simulation import SimulationSettings, simulate_campaign
from robocal_uncertainty.errors import InputError

REPO = Path(__file__).resolve().parents[2]
UR10 = REPO / "config" / "ur10.yaml"
SERIES = REPO / "test" / "data" / "ur10_laser_tracker" / "measurements_iso_cubes.csv"


def test_6dof_campaign_roundtrip(tmp_path: Path) -> None:
    sim = simulate_campaign(load_robot_model(UR10), SimulationSettings(frame="tracker", orientation_std=1e-4), seed=3)
    path = tmp_path / "c.mcap"
    write_campaign(path, sim.campaign)
    back = read_campaign(path)
    assert back.measurement == sim.campaign.measurement
    np.testing.assert_allclose(back.points, sim.campaign.points, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(back.points[:, :3], sim.campaign.points[:, :3])
    assert back.point_std is not None
    assert sim.campaign.point_std is not None
    np.testing.assert_array_equal(back.point_std, sim.campaign.point_std)


def test_point_campaign_file_is_unchanged(tmp_path: Path) -> None:
    sim = simulate_campaign(load_robot_model(UR10), SimulationSettings(frame="tracker"), seed=3)
    write_campaign(tmp_path / "a.mcap", sim.campaign)
    back = read_campaign(tmp_path / "a.mcap")
    assert back.measurement.name == "point"
    np.testing.assert_array_equal(back.points, sim.campaign.points)
    assert b"/tracker/pose" not in (tmp_path / "a.mcap").read_bytes()


@pytest.mark.parametrize(
    ("quaternion", "match"),
    [([0.0, 0.0, 0.0, 2.0], "not a unit quaternion"), ([np.nan, 0.0, 0.0, 1.0], "NaN")],
)
def test_bad_quaternion_is_a_one_line_error(tmp_path: Path, quaternion: list[float], match: str) -> None:
    meas = PoseMeasurement((1e-5,) * 3, (1e-4,) * 3)
    with (
        CampaignRecorder(
            tmp_path / "b.mcap", joint_names=("j1",), frame="tracker", frame_id="t", measurement=meas
        ) as rec,
        pytest.raises(InputError, match=match) as info,
    ):
        rec.append(0, [0.1], [1.0, 2.0, 3.0], [1e-5] * 3, quaternion, [1e-4] * 3)
    assert "\n" not in str(info.value)


def test_import_csv_orientation_to_a_6dof_campaign(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ur10.mcap"
    code = main(["import-csv", str(SERIES), "--out", str(out), "--orientation-convention", "intrinsic_xyz"])
    assert code == 0
    campaign = read_campaign(out)
    assert isinstance(campaign.measurement, PoseMeasurement)
    assert campaign.points.shape == (632, 12)
    assert campaign.metadata["orientation_convention"] == "intrinsic_xyz"
    code = main(["import-csv", str(SERIES), "--out", str(out), "--force", "--orientation-convention", "extrinsic_xyz"])
    assert code != 0
    assert "intrinsic_xyz Euler angles" in capsys.readouterr().err
