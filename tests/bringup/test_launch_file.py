"""The ros2 launch file (not runnable here: PyPI has no launch) starts the nodes explore.sh starts."""

import ast
import re
from importlib.metadata import distribution
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _console_scripts(package: str) -> set:
    return {ep.name for ep in distribution(package).entry_points if ep.group == "console_scripts"}


def test_launch_file_nodes_exist_and_match_explore_sh():
    source = (ROOT / "src/tactile_bringup/launch/explore.launch.py").read_text()
    ast.parse(source)
    launched = set(re.findall(r'node\("(\w+)", "(\w+)"', source))
    for executable, package in launched:
        assert executable in _console_scripts(package), f"{package} has no executable {executable}"
    script = (ROOT / "scripts/explore.sh").read_text()
    started = set(re.findall(r"^\s*start (\w+)\s*$", script, flags=re.M))
    assert {e for e, _ in launched} == started
