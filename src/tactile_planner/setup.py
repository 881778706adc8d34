"""ament_python package tactile_planner: builds with colcon (apt ROS 2) and pip (PyPI ROS 2 wheels)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_planner"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="Tactile exploration team",
    maintainer_email="rig@example.org",
    description="Free-space graph, linearly solvable MDP travel costs, touch selection strategies (ROS-free) and the SOC planner node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "soc_planner = tactile_planner.node:main",
        ],
    },
)
