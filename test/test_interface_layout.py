"""The ROS interface files are installable as they are: regular files in msg/ and srv/ (a
symlink is installed dangling into share/, issue 12), listed in CMakeLists.txt, identical to
the Python package data, parsed by rosbags, with the fields the nodes use, and every ROS
package the nodes import is declared in package.xml. CI has no ROS; ``ros2 interface show``
on the installed result is a check by hand."""

from __future__ import annotations

import ast
import configparser
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from rosbags.typesys import get_types_from_msg

from robocal_uncertainty.bagio.messages import MESSAGE_NAMES, message_definition

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "robocal_uncertainty"
MSG_FILES = sorted((REPO / "msg").iterdir())
SRV_FILES = sorted((REPO / "srv").iterdir())

# Fields the nodes and converters read or write (bagio/messages.py, nodes/*.py).
FIELDS_USED = {
    "CalibrationSample": {
        "header",
        "joint_names",
        "joint_positions",
        "joint_position_std",
        "point",
        "point_covariance",
        "joint_state_count",
        "tracker_point_count",
        "has_orientation",
        "orientation",
        "orientation_covariance",
    },
    "CalibrationResult": {
        "header",
        "model_name",
        "parameter_names",
        "estimate",
        "lambda_value",
        "lambda_method",
        "condition_number",
        "rms_after",
        "sample_count",
    },
    "PoseUncertainty": {"header", "joint_positions", "mean", "covariance", "standard_uncertainty", "trials"},
}
SRV_FIELDS_USED = {
    "SuggestPoses": (
        {"count", "candidates", "candidate_count", "monte_carlo_check", "trials", "seed"},
        {
            "success",
            "message",
            "joint_names",
            "joint_positions",
            "current_u",
            "predicted_u",
            "monte_carlo_current_u",
            "monte_carlo_u",
            "frame_id",
        },
    ),
    "CompensateTargets": (
        {"targets", "use_orientation", "seed_joints", "trials", "seed"},
        {
            "success",
            "message",
            "joint_names",
            "joint_positions",
            "status",
            "position_error",
            "standard_uncertainty",
            "expanded_uncertainty",
            "coverage_probability",
            "trials",
            "frame_id",
        },
    ),
}


def _cmake_interfaces() -> list[str]:
    text = (REPO / "CMakeLists.txt").read_text(encoding="utf-8")
    block = re.search(r"set\(_interfaces(.*?)\)", text, re.DOTALL)
    assert block, "CMakeLists.txt lists the interfaces in set(_interfaces ...)"
    assert "rosidl_generate_interfaces(${PROJECT_NAME}\n  ${_interfaces}" in text
    return re.findall(r'"([^"]+)"', block.group(1))


def _fields(text: str, name: str) -> set[str]:
    types = get_types_from_msg(text, f"robocal_uncertainty/msg/{name}")
    (_, (_, fields)), *_ = types.items()
    return {field_name for field_name, _ in fields}


@pytest.mark.parametrize("path", MSG_FILES + SRV_FILES, ids=lambda p: p.name)
def test_interface_files_are_regular_files(path: Path) -> None:
    assert not path.is_symlink(), f"{path} is a symlink: it would be installed dangling"
    assert path.is_file()


def test_cmake_generates_exactly_the_files_in_msg_and_srv() -> None:
    listed = _cmake_interfaces()
    assert sorted(listed) == sorted(f"{p.parent.name}/{p.name}" for p in MSG_FILES + SRV_FILES)
    assert all(Path(name).suffix in (".msg", ".srv") for name in listed)
    text = (REPO / "CMakeLists.txt").read_text(encoding="utf-8")
    # The configure-time guard, and no rule installing msg/ or srv/ by hand (rosidl does).
    assert "IS_SYMLINK" in text and "FATAL_ERROR" in text
    assert not re.search(r"install\(\s*(DIRECTORY|FILES)\s+\"?(\$\{CMAKE_CURRENT_SOURCE_DIR\}/)?(msg|srv)\b", text)


@pytest.mark.parametrize("path", MSG_FILES, ids=lambda p: p.name)
def test_msg_files_equal_the_package_data_and_parse(path: Path) -> None:
    typename = f"robocal_uncertainty/msg/{path.stem}"
    assert typename in MESSAGE_NAMES
    text = path.read_text(encoding="utf-8")
    assert text == message_definition(typename)
    assert (PACKAGE / "msg_definitions" / path.name).read_bytes() == path.read_bytes()
    assert not (PACKAGE / "msg_definitions" / path.name).is_symlink()
    assert FIELDS_USED[path.stem] <= _fields(text, path.stem)


def test_package_data_holds_every_message() -> None:
    assert {p.name for p in (PACKAGE / "msg_definitions").glob("*.msg")} == {p.name for p in MSG_FILES}
    assert {n.rsplit("/", 1)[-1] + ".msg" for n in MESSAGE_NAMES} == {p.name for p in MSG_FILES}
    config = configparser.ConfigParser()
    config.read(REPO / "setup.cfg", encoding="utf-8")
    patterns = [p.strip() for p in config["options.package_data"]["robocal_uncertainty"].split(",")]
    assert "msg_definitions/*.msg" in patterns


@pytest.mark.parametrize("path", SRV_FILES, ids=lambda p: p.name)
def test_srv_files_parse_with_the_fields_the_node_uses(path: Path) -> None:
    request, response = path.read_text(encoding="utf-8").split("\n---\n")
    want_request, want_response = SRV_FIELDS_USED[path.stem]
    assert want_request <= _fields(request, f"{path.stem}_Request")
    assert want_response <= _fields(response, f"{path.stem}_Response")


def _ros_packages_imported_by_nodes() -> set[str]:
    packages = set()
    for source in (PACKAGE / "nodes").glob("*.py"):
        for node in ast.walk(ast.parse(source.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                root, _, sub = node.module.partition(".")
                if sub.split(".")[0] in ("msg", "srv") and root != "robocal_uncertainty":
                    packages.add(root)
    return packages


def test_package_xml_declares_every_interface_package_the_nodes_import() -> None:
    root = ET.parse(REPO / "package.xml").getroot()
    declared = {e.text for e in root if e.tag in ("depend", "exec_depend", "build_depend")}
    used = _ros_packages_imported_by_nodes()
    assert {"diagnostic_msgs", "visualization_msgs"} <= used
    assert used <= declared, used - declared
    assert root.find("member_of_group").text == "rosidl_interface_packages"
    assert "rosidl_default_generators" in {e.text for e in root.findall("buildtool_depend")}
