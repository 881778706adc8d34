"""The environment ROS needs, for console scripts called without ``tactile.env``.

``ament_index_python`` (package share folders, config files) raises when
``AMENT_PREFIX_PATH`` is unset, and the PyPI ROS wheels do not set it; DDS
discovery would use the whole subnet when ``ROS_AUTOMATIC_DISCOVERY_RANGE``
is unset. ``ensure_ros_environment`` fills in what is missing, and only that:
the prefix of the running Python (the virtualenv, where our packages' share/
entries live) and discovery on this host. Values a user has set are kept.
It runs when :mod:`tactile_common` is imported, which every node, the
offline runner and the benchmark do before any lookup or ``rclpy.init``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path


def ensure_ros_environment() -> None:
    """Set ``AMENT_PREFIX_PATH`` (from ``sys.prefix``) and the discovery range if unset."""
    if not os.environ.get("AMENT_PREFIX_PATH"):
        prefix = Path(sys.prefix)
        if (prefix / "share" / "ament_index").is_dir():
            os.environ["AMENT_PREFIX_PATH"] = str(prefix)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
