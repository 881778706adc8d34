"""Each package.xml declares what the package's Python code imports, and nothing else.

The imports are read from the sources (ast: every ``import``, also inside
functions; the package's modules and its launch files). Each top-level module
maps to a rosdep key through ``MODULE_TO_ROSDEP``; a third-party module that
is not in the map fails the test until someone names its key.
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGES = sorted(p.name for p in SRC.iterdir() if (p / "package.xml").exists())

# Top-level import -> rosdep key (rosdistro's rosdep/base.yaml and python.yaml, or a ROS package).
MODULE_TO_ROSDEP = {
    "rclpy": "rclpy",
    "ament_index_python": "ament_index_python",
    "launch": "launch",
    "launch_ros": "launch_ros",
    **{m: m for m in (
        "builtin_interfaces", "diagnostic_msgs", "geometry_msgs", "nav_msgs", "rcl_interfaces",
        "rosgraph_msgs", "sensor_msgs", "std_msgs", "std_srvs", "trajectory_msgs", "visualization_msgs",
    )},
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
    "serial": "python3-serial",
    "matplotlib": "python3-matplotlib",
    "mpl_toolkits": "python3-matplotlib",
    "pinocchio": "pinocchio",
    # No rosdep key in rosdistro for these (PyPI wheels here); the names follow the conventions.
    "example_robot_data": "example-robot-data",
    "mcap": "python3-mcap",
    "contourpy": "python3-contourpy",  # not in rosdistro either; Debian/Ubuntu's package name
    "distributed": "python3-distributed",  # Dask's scheduler client (Debian/Ubuntu's package name)
    **{p: p for p in PACKAGES},
}

# Runtime dependencies that no Python import shows (key -> why). Empty today.
NOT_IMPORTED = {}


def _top_level_imports(files) -> dict[str, set[str]]:
    """Top-level module -> the files importing it (absolute imports only)."""
    found: dict[str, set[str]] = {}
    for f in files:
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module]
            else:
                continue
            for name in names:
                found.setdefault(name.split(".")[0], set()).add(f.name)
    return found


def _package_imports(pkg: str) -> dict[str, set[str]]:
    root = SRC / pkg
    files = sorted((root / pkg).rglob("*.py")) + sorted((root / "launch").glob("*.py"))
    imports = _top_level_imports(files)
    return {m: f for m, f in imports.items() if m != pkg and m not in sys.stdlib_module_names}


def _exec_depends(pkg: str) -> set[str]:
    tree = ET.parse(SRC / pkg / "package.xml")
    return {e.text.strip() for tag in ("exec_depend", "depend") for e in tree.getroot().iter(tag)}


def test_packages_found():
    assert {"tactile_common", "tactile_gpis", "tactile_planner", "tactile_driver", "tactile_sim",
            "tactile_bringup"} <= set(PACKAGES)


@pytest.mark.parametrize("pkg", PACKAGES)
def test_every_import_has_its_exec_depend(pkg):
    imports = _package_imports(pkg)
    unmapped = sorted(m for m in imports if m not in MODULE_TO_ROSDEP)
    assert not unmapped, f"{pkg} imports {unmapped}: add each to MODULE_TO_ROSDEP with its rosdep key"
    declared = _exec_depends(pkg)
    missing = sorted(f"{MODULE_TO_ROSDEP[m]} (import {m} in {sorted(files)})"
                     for m, files in imports.items() if MODULE_TO_ROSDEP[m] not in declared)
    assert not missing, f"{pkg}/package.xml lacks <exec_depend> for: {missing}"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_exec_depend_without_an_import(pkg):
    used = {MODULE_TO_ROSDEP[m] for m in _package_imports(pkg) if m in MODULE_TO_ROSDEP}
    unused = sorted(_exec_depends(pkg) - used - set(NOT_IMPORTED))
    assert not unused, f"{pkg}/package.xml declares {unused}, which its code does not import: remove them"


def test_the_check_sees_a_missing_dependency(tmp_path):
    """The import scan itself: a lazy import inside a function counts."""
    f = tmp_path / "m.py"
    f.write_text("import os\n\ndef f():\n    from scipy.sparse import csr_matrix\n    import serial.tools\n")
    assert set(_top_level_imports([f])) == {"os", "scipy", "serial"}
