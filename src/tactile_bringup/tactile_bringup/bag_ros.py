"""rclpy-side helpers shared by the recorder and player nodes.

Message classes from type names, and rclpy QoS profiles to/from the plain
dicts of rosbag2's ``offered_qos_profiles`` (:mod:`tactile_bringup.mcap_recorder`).
"""

from __future__ import annotations

import importlib
from types import SimpleNamespace
from typing import Any, Dict, List, Mapping, Sequence, Tuple

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from tactile_bringup.mcap_recorder import qos_profile_dict
from tactile_bringup.msgdefs import split_type_name
from tactile_common.params import declare_parameters


def message_class(type_name: str) -> Any:
    """The Python class of ``pkg/msg/Type``; ValueError if the package is not installed."""
    package, namespace, name = split_type_name(type_name)
    try:
        return getattr(importlib.import_module(f"{package}.{namespace}"), name)
    except (ImportError, AttributeError):
        raise ValueError(f"message type '{type_name}' is not installed") from None


def _policy_name(policy: Any) -> str:
    return policy.name.lower()


def qos_to_dict(profile: QoSProfile) -> Dict[str, Any]:
    """An rclpy (offered) QoS profile as a rosbag2 QoS dict."""
    return qos_profile_dict(
        history=_policy_name(profile.history),
        depth=profile.depth,
        reliability=_policy_name(profile.reliability),
        durability=_policy_name(profile.durability),
        deadline_ns=profile.deadline.nanoseconds,
        lifespan_ns=profile.lifespan.nanoseconds,
        liveliness=_policy_name(profile.liveliness),
        liveliness_lease_duration_ns=profile.liveliness_lease_duration.nanoseconds,
        avoid_ros_namespace_conventions=profile.avoid_ros_namespace_conventions,
    )


def adapted_qos(
    offers: Sequence[Mapping[str, Any]], volatile_depth: int, latched_depth: int = 1
) -> QoSProfile:
    """A QoS compatible with every offer and as strong as all of them (rosbag2's rule).

    RELIABLE if every offer is reliable, else BEST_EFFORT; TRANSIENT_LOCAL if
    every offer is transient-local (latched), else VOLATILE; KEEP_LAST with
    depth = max(``latched_depth`` or ``volatile_depth``, the offers' depths;
    discovered offers carry depth 0). No offers: RELIABLE, VOLATILE.
    """
    reliable = all(str(o.get("reliability", "")).lower() == "reliable" for o in offers)
    latched = bool(offers) and all(
        str(o.get("durability", "")).lower() == "transient_local" for o in offers
    )
    base = latched_depth if latched else volatile_depth
    depth = max([int(base)] + [int(o.get("depth", 0)) for o in offers])
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(depth, 1),
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        liveliness=LivelinessPolicy.AUTOMATIC,
        deadline=Duration(),
        lifespan=Duration(),
    )


def string_list_parameter(node: Node, name: str, description: str) -> List[str]:
    """Declare a string-array parameter that may be left unset (= empty list)."""
    try:
        value = node.declare_parameter(
            name, Parameter.Type.STRING_ARRAY, ParameterDescriptor(description=description)
        ).value
    except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
        raise ValueError(f"bad parameter: {exc} (expected a list of strings, e.g. \"['/a', '/b']\")") from None
    return [str(v) for v in (value or []) if str(v)]


def declare_checked(node: Node, spec: Mapping[str, Tuple[Any, str]]) -> SimpleNamespace:
    """``declare_parameters``, with a wrongly typed override as a ValueError (a message, no traceback)."""
    try:
        return declare_parameters(node, spec)
    except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
        raise ValueError(f"bad parameter: {exc}") from None
