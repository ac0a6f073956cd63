"""package.xml for a ROS user: every rosdep key resolves on Jazzy, test-only packages are
test dependencies, and the license is the one the repository ships (no ROS needed)."""

from __future__ import annotations

import ast
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
KEYS = REPO / "test" / "data" / "rosdep_keys_jazzy.txt"


def _manifest() -> ET.Element:
    return ET.parse(REPO / "package.xml").getroot()


def _known_keys() -> dict[str, str]:
    """Key -> rosdistro file it was found in (the dated list in the test data)."""
    out = {}
    for line in KEYS.read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            key, source = line.split()
            out[key] = source
    return out


def test_every_rosdep_key_of_package_xml_exists_on_rosdistro() -> None:
    keys = {e.text for e in _manifest() if e.tag.endswith("depend")}
    known = _known_keys()
    assert "python3-mcap-pip" not in known  # the key that broke `rosdep install`
    assert keys - set(known) == set(), f"not rosdep keys on Jazzy: {sorted(keys - set(known))}"


def test_pip_only_dependencies_are_keys_for_the_pip_packages_setup_cfg_requires() -> None:
    exec_keys = {e.text for e in _manifest() if e.tag in ("depend", "exec_depend")}
    known = _known_keys()
    # rosbags and mcap (through mcap-ros2-support) come from pip: both from rosdep/python.yaml.
    assert {"python3-rosbags-pip", "mcap-ros2-support"} <= exec_keys
    assert known["python3-rosbags-pip"] == known["mcap-ros2-support"] == "rosdep/python.yaml"
    setup = (REPO / "setup.cfg").read_text(encoding="utf-8")
    for requirement in ("rosbags", "mcap", "numpy", "scipy", "PyYAML", "matplotlib", "tqdm"):
        assert f"    {requirement}>=" in setup


def _imported_roots(folder: Path) -> set[str]:
    roots = set()
    for source in folder.rglob("*.py"):
        for node in ast.walk(ast.parse(source.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                roots |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                roots.add(node.module.split(".")[0])
    return roots


def test_pinocchio_is_a_test_dependency_only() -> None:
    root = _manifest()
    assert "pinocchio" not in _imported_roots(REPO / "robocal_uncertainty")
    tests = "".join(path.read_text(encoding="utf-8") for path in (REPO / "test" / "core").rglob("*.py"))
    assert 'importorskip("pinocchio")' in tests  # the kinematics tests' independent reference
    assert "pinocchio" in {e.text for e in root.findall("test_depend")}
    assert "pinocchio" not in {e.text for e in root if e.tag in ("depend", "exec_depend")}


def test_license_file_and_maintainer() -> None:
    root = _manifest()
    assert root.find("license").text == "Apache-2.0"
    text = (REPO / "LICENSE").read_text(encoding="utf-8")
    assert "Apache License" in text and "Version 2.0, January 2004" in text
    assert "license = Apache-2.0" in (REPO / "setup.cfg").read_text(encoding="utf-8")
    email = root.find("maintainer").get("email")
    assert email and not email.endswith(".invalid")
