"""The robot format seam: one registry decides the format of a robot name, one loader reads it
for the command line, the nodes and export, and every chain it gives satisfies the protocol.

References: the shipped UR10 read from its DH YAML (an independent description of the same
robot) for the URDF reader; the URDF text path for the URDF file path."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import robocal_uncertainty
from robocal_uncertainty.core.kinematics import forward_points
from robocal_uncertainty.core.robot_formats import (
    EXPORT_FORMATS,
    ROBOT_FORMATS,
    load_robot_source,
    robot_format_named,
    robot_format_of,
    robot_source_from_description,
)
from robocal_uncertainty.core.robot_formats.protocol import KinematicChain
from robocal_uncertainty.errors import ConfigError

PACKAGE = Path(__file__).resolve().parents[2] / "robocal_uncertainty"  # the source tree, for its text
# The package under test's own data: in CI's matrix that is the installed copy, not the checkout.
UR10_URDF = Path(robocal_uncertainty.__file__).resolve().parent / "data" / "ur10.urdf"


def test_the_format_of_a_name_is_decided_by_its_suffix() -> None:
    assert robot_format_of("arm.urdf").name == "urdf"
    assert robot_format_of("ARM.URDF").name == "urdf"
    for name in ("arm.yaml", "arm.yml", "ur10", "paper_arm", "arm.txt"):
        assert robot_format_of(name).name == "yaml"
    assert EXPORT_FORMATS == ("urdf", "ur-kinematics", "yaml")
    assert not robot_format_named("ur-kinematics").readable
    for fmt in ROBOT_FORMATS:  # each module has the functions its flags promise
        module = fmt.load()
        assert hasattr(module, "read_robot") == fmt.readable
        assert hasattr(module, "write_calibrated") == fmt.writable


def test_the_urdf_suffix_is_named_in_one_place() -> None:
    hits = [
        str(path.relative_to(PACKAGE))
        for path in PACKAGE.rglob("*.py")
        if re.search(r"""["']\.urdf["']""", path.read_text(encoding="utf-8"))
    ]
    assert hits == ["core/robot_formats/registry.py"]


def test_a_urdf_file_is_the_dh_robot_it_describes() -> None:
    point = [0.0, 0.0, 0.109]
    urdf = load_robot_source(str(UR10_URDF), base_link="base", tip_link="tool0", tool_point=point)
    text = robot_source_from_description(UR10_URDF.read_text(), base_link="base", tip_link="tool0", tool_point=point)
    dh = load_robot_source("ur10").model  # probe at 109 mm, DH frame 0 = UR's base
    q = np.random.default_rng(3).uniform(-np.pi, np.pi, size=(25, 6))
    np.testing.assert_allclose(
        forward_points(urdf.model, urdf.model.parameter_vector(), q),
        forward_points(dh, dh.parameter_vector(), q),
        rtol=0,
        atol=1e-12,
    )
    np.testing.assert_array_equal(urdf.model.parameter_vector(), text.model.parameter_vector())
    assert urdf.from_urdf and urdf.urdf is not None and urdf.model.tool_known
    assert not load_robot_source(str(UR10_URDF), base_link="base", tip_link="tool0").model.tool_known


def test_a_dh_model_reads_its_urdf_only_when_asked() -> None:
    source = load_robot_source("ur10", base_known=False)
    assert source.urdf is None and source.structure_file == UR10_URDF
    assert not source.model.base_known
    assert "base" in source.with_structure().urdf.links  # type: ignore[union-attr]
    assert load_robot_source("paper_arm").structure_file is None


def test_a_robot_yaml_refuses_a_tool_point_given_apart() -> None:
    with pytest.raises(ConfigError, match="gives its own tool_point"):
        load_robot_source("paper_arm", tool_point=[0.0, 0.0, 0.1])


def test_every_chain_read_satisfies_the_protocol() -> None:
    for source in (load_robot_source("paper_arm"), load_robot_source(str(UR10_URDF))):
        assert isinstance(source.model, KinematicChain)
