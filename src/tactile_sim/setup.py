"""ament_python package tactile_sim: builds with colcon (apt ROS 2) and pip (PyPI ROS 2 wheels)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "tactile_sim"

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
    description="Simulated rig: objects as signed distance functions, metrics, simulated sensor device, emulated ros2_control controller.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "sim_rig = tactile_sim.rig_node:main",
            "sim_sensor_device = tactile_sim.sensor_device_node:main",
        ],
    },
)
