"""ament_python package tactile_driver: builds with colcon (apt ROS 2) and pip (PyPI ROS 2 wheels)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_driver"

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
    description="Tactile sensor protocol and driver node, Pinocchio 7-DOF arm commander node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "arm_commander = tactile_driver.commander_node:main",
            "tactile_sensor = tactile_driver.sensor_node:main",
        ],
    },
)
