"""Declare a node's parameters from one table of defaults and descriptions.

Keeps each node's parameter list in one place (the node file), typed by its
default, with the description that ``ros2 param describe`` shows.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, Mapping, Tuple

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node


def declare_parameters(
    node: Node, spec: Mapping[str, Tuple[Any, str]]
) -> SimpleNamespace:
    """Declare ``name -> (default, description)`` and return their current values.

    Names may contain dots (``kernel.length_scale_m``); the namespace returned
    uses underscores for dots. A list default must be non-empty (its element
    type types the parameter).
    """
    values = {}
    for name, (default, description) in spec.items():
        param = node.declare_parameter(
            name, default, ParameterDescriptor(description=description)
        )
        values[name.replace(".", "_")] = param.value
    return SimpleNamespace(**values)
