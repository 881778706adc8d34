"""The workspace builds with colcon (the path of users with apt ROS 2).

Builds a temporary copy of ``ros2_ws`` with colcon from PyPI and checks that
every console script of every package lands in ``install/<pkg>/lib/<pkg>/``
(where ``ros2 run`` looks) and that config files land in ``share/<pkg>``.
"""

import shutil
import subprocess
from importlib.metadata import distribution
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = sorted(p.name for p in (ROOT / "src").iterdir() if (p / "package.xml").exists())

pytestmark = pytest.mark.slow


def test_colcon_build_installs_console_scripts(tmp_path):
    colcon = shutil.which("colcon")
    assert colcon, "colcon is installed by scripts/setup.sh"
    ws = tmp_path / "ws"
    ws.mkdir()
    shutil.copytree(ROOT / "src", ws / "src", ignore=shutil.ignore_patterns("*.egg-info", "__pycache__"))
    result = subprocess.run([colcon, "build", "--event-handlers", "console_direct-"],
                            cwd=ws, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    for pkg in PACKAGES:
        scripts = [ep.name for ep in distribution(pkg).entry_points if ep.group == "console_scripts"]
        for script in scripts:
            assert (ws / "install" / pkg / "lib" / pkg / script).is_file(), f"{pkg}: {script} not installed"
        assert (ws / "install" / pkg / "share" / pkg / "package.xml").is_file()
        for cfg in (ROOT / "src" / pkg / "config").glob("*.yaml"):
            assert (ws / "install" / pkg / "share" / pkg / "config" / cfg.name).is_file()
    assert "cloud_talker" in [ep.name for ep in distribution("tactile_common").entry_points]


def test_ros2_ws_points_at_the_packages():
    assert sorted(p.name for p in (ROOT / "ros2_ws" / "src").iterdir() if (p / "package.xml").exists()) == PACKAGES
