"""Declare a node's parameters from its table, with types, ranges and read-only flags.

The table (``name: (default, description[, Rule])``, see
:mod:`tactile_common.param_spec`) is the only place a parameter is defined.
Each parameter is declared with a descriptor carrying the description, the
range (``FloatingPointRange`` / ``IntegerRange`` for scalar numbers), the
allowed values in words (``additional_constraints``) and ``read_only`` unless
the rule says the node honours changes (``dynamic``). The value a node starts
with is checked against the rule (a bad one is a ``ValueError`` naming the
value and what is allowed: the node logs it and exits with status 2), and an
on-set callback rejects a later ``set_parameters`` that breaks the rule, with
the reason. rclpy itself rejects a change of a read-only parameter ("Trying to
set a read-only parameter: <name>").
"""

from __future__ import annotations

import math
import sys
from types import SimpleNamespace
from typing import Any, Mapping, Sequence

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node

from .param_spec import ParamSpec, check_value, specs

_INT64_MAX = 2**63 - 1


def descriptor(s: ParamSpec, param_type: int) -> ParameterDescriptor:
    """The ROS descriptor of one table entry (``param_type``: its ``Parameter.Type`` value)."""
    d = ParameterDescriptor(description=s.description, type=param_type, read_only=s.read_only,
                            additional_constraints=s.constraints_text())
    r = s.rule
    if s.type_name == "double" and any(b is not None for b in (r.gt, r.ge, r.lt, r.le)):
        lo = r.gt if r.gt is not None else r.ge if r.ge is not None else -sys.float_info.max
        hi = r.lt if r.lt is not None else r.le if r.le is not None else sys.float_info.max
        d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    elif s.type_name == "integer" and any(b is not None for b in (r.gt, r.ge, r.lt, r.le)):
        lo = (math.floor(r.gt) + 1 if r.gt is not None else math.ceil(r.ge) if r.ge is not None else -_INT64_MAX)
        hi = (math.ceil(r.lt) - 1 if r.lt is not None else math.floor(r.le) if r.le is not None else _INT64_MAX)
        d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
    return d


def declare_parameters(node: Node, spec: Mapping[str, Sequence[Any]]) -> SimpleNamespace:
    """Declare every entry of ``spec`` and return the values as a namespace.

    Names may contain dots (``kernel.length_scale_m``); the namespace uses
    underscores for dots. A list default must be non-empty (its element type
    types the parameter). Attributes of ``dynamic`` parameters follow later
    successful ``set_parameters`` calls; the others never change.

    Raises:
        ValueError: a start-up value of the wrong type or outside its rule
            (one line naming the parameter, the value and what is allowed).
    """
    table = specs(spec)
    values = {}
    for name, s in table.items():
        try:
            param = node.declare_parameter(name, s.default, ParameterDescriptor(description=s.description))
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            raise ValueError(f"{node.get_name()}: parameter {name}: {exc} ({s.constraints_text()})") from None
        reason = check_value(s, param.value, f"{node.get_name()}: ")
        if reason:
            raise ValueError(f"{reason} ({s.description})")
        node.set_descriptor(name, descriptor(s, param.type_.value))
        values[name.replace(".", "_")] = param.value
    namespace = SimpleNamespace(**values)

    def on_set(parameters) -> SetParametersResult:
        reasons = [check_value(table[p.name], p.value) for p in parameters if p.name in table]
        reasons = [r for r in reasons if r]
        if reasons:
            return SetParametersResult(successful=False, reason="; ".join(reasons))
        return SetParametersResult(successful=True)

    def after_set(parameters) -> None:
        for p in parameters:
            if p.name in table and table[p.name].rule.dynamic:
                setattr(namespace, p.name.replace(".", "_"), p.value)

    node.add_on_set_parameters_callback(on_set)
    node.add_post_set_parameters_callback(after_set)
    return namespace
