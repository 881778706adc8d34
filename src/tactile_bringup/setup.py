"""ament_python package tactile_bringup: builds with colcon (apt ROS 2) and pip (PyPI ROS 2 wheels)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_bringup"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/config", glob("config/*.yaml") + glob("config/*.json") + glob("config/*.rviz")),
        ("share/" + PACKAGE + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="Tactile exploration team",
    maintainer_email="rig@example.org",
    description="Configuration, launch, MCAP recorder/player, exploration runner and benchmarks.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder = tactile_bringup.recorder_node:main",
            "player = tactile_bringup.player_node:main",
            "tactile-explore-offline = tactile_bringup.explore_offline:main",
            "tactile-benchmark = tactile_bringup.benchmark:main",
            "explorer = tactile_bringup.explorer_node:main",
            "viz = tactile_bringup.viz_node:main",
        ],
    },
)
