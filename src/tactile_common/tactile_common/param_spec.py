"""Parameter tables: the type, range and mutability of every node parameter, ROS-free.

A node's table maps each parameter name to ``(default, description)`` or
``(default, description, rule)``, the rule a :class:`Rule` or the same as a
dict (``{"gt": 0.0}``, ``{"choices": ("2d", "3d"), "dynamic": True}``). The default fixes the type (bool,
integer, double, string, or an array of one of them, as ROS types a
parameter); the :class:`Rule` adds the allowed values and whether the running
node honours a change (``dynamic``; every other parameter is read once at
start-up, so the node declares it read-only). The same entry is checked on
the node (:func:`tactile_common.params.declare_parameters`: descriptors and an
on-set callback) and before any node starts (:func:`check_value`, used on the
command line and on parameter files), so the two can never disagree.

Importing this module pulls in nothing but the standard library.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, NamedTuple, Optional, Sequence

#: Parameters rclpy declares on every node itself.
ROS_BUILTIN: dict[str, tuple] = {
    "use_sim_time": (False, "use /clock for the node clock"),
    "start_type_description_service": (True, "serve the node's type descriptions"),
}


@dataclass(frozen=True)
class Rule:
    """Allowed values of one parameter (each bound applies to every array element).

    Attributes:
        gt, ge, lt, le: strict / inclusive lower and upper bounds (numbers).
        choices: the allowed values (strings or numbers).
        length: arrays: exactly this many elements.
        increasing: arrays: strictly increasing (an interval ``[min, max]``).
        dynamic: the running node reads the value again (``ros2 param set``
            takes effect); otherwise the parameter is read-only.
    """

    gt: Optional[float] = None
    ge: Optional[float] = None
    lt: Optional[float] = None
    le: Optional[float] = None
    choices: Optional[Sequence[Any]] = None
    length: Optional[int] = None
    increasing: bool = False
    dynamic: bool = False

    def text(self) -> str:
        """The rule in words: ``> 0``, ``in [0, 1]``, ``one of 'a', 'b'``, ``3 values``."""
        parts = []
        lo = f"> {_num(self.gt)}" if self.gt is not None else f"≥ {_num(self.ge)}" if self.ge is not None else ""
        hi = f"< {_num(self.lt)}" if self.lt is not None else f"≤ {_num(self.le)}" if self.le is not None else ""
        if lo and hi:
            parts.append(f"{lo} and {hi}")
        elif lo or hi:
            parts.append(lo or hi)
        if self.choices is not None:
            parts.append("one of " + ", ".join(repr(c) for c in self.choices))
        if self.length is not None:
            parts.append(f"{self.length} values")
        if self.increasing:
            parts.append("increasing")
        return ", ".join(parts)

    def element_reason(self, v: Any) -> Optional[str]:
        """Why one (scalar) value breaks the rule, or None."""
        if self.choices is not None and v not in self.choices:
            return "must be one of " + ", ".join(repr(c) for c in self.choices)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            ok = ((self.gt is None or v > self.gt) and (self.ge is None or v >= self.ge)
                  and (self.lt is None or v < self.lt) and (self.le is None or v <= self.le))
            if not ok:  # NaN fails every bound
                bounds = Rule(gt=self.gt, ge=self.ge, lt=self.lt, le=self.le).text()
                return f"must be {bounds}"
        return None


#: No constraint beyond the type.
ANY = Rule()


class ParamSpec(NamedTuple):
    """One table entry, normalised."""

    name: str
    default: Any
    description: str
    rule: Rule
    type_name: str  # 'bool', 'integer', 'double', 'string', 'double[]', ...

    @property
    def read_only(self) -> bool:
        return not self.rule.dynamic

    def constraints_text(self) -> str:
        """What ``ros2 param describe`` shows as the additional constraints."""
        allowed = self.rule.text()
        mut = "changeable while running" if self.rule.dynamic else "read-only: read at start-up (restart the node)"
        return f"{self.type_name}{', ' + allowed if allowed else ''}; {mut}"


def _num(v: float) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _scalar_type(v: Any) -> str:
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, int):
        return "integer"
    if isinstance(v, float):
        return "double"
    if isinstance(v, str):
        return "string"
    raise TypeError(f"unsupported parameter default {v!r}")


def type_name(default: Any) -> str:
    """ROS type of a default: ``double``, ``string[]``, ..."""
    if isinstance(default, (list, tuple)):
        if not default:
            raise TypeError("a list default must be non-empty (its element type types the parameter)")
        return _scalar_type(default[0]) + "[]"
    return _scalar_type(default)


def spec(name: str, entry: Sequence[Any]) -> ParamSpec:
    """Normalise ``(default, description[, rule])``."""
    if len(entry) not in (2, 3):
        raise TypeError(f"parameter table entry '{name}' must be (default, description[, Rule])")
    default, description = entry[0], entry[1]
    rule = entry[2] if len(entry) == 3 else ANY
    if isinstance(rule, Mapping):  # tables outside tactile_common may write the rule as a dict
        rule = Rule(**rule)
    return ParamSpec(name, default, description, rule, type_name(default))


def specs(table: Mapping[str, Sequence[Any]]) -> dict[str, ParamSpec]:
    return {name: spec(name, entry) for name, entry in table.items()}


def defaults(table: Mapping[str, Sequence[Any]]) -> dict[str, Any]:
    """``{name: default}`` of a table."""
    return {name: entry[0] for name, entry in table.items()}


def _show(value: Any) -> str:
    return repr(value) if isinstance(value, str) else str(value).replace("True", "true").replace("False", "false")


def _type_reason(expected: str, v: Any) -> Optional[str]:
    got = _scalar_type(v) if isinstance(v, (bool, int, float, str)) else type(v).__name__
    if got == expected:
        return None
    if expected == "double" and got == "integer":
        return f"must be a double: write {v}.0 (ROS reads {v} as an integer)"
    return f"must be a{'n' if expected[0] in 'ai' else ''} {expected}, not a{'n' if got[0] in 'ai' else ''} {got}"


def value_reason(s: ParamSpec, value: Any) -> Optional[str]:
    """Why ``value`` is not allowed for ``s`` (type, then rule), or None."""
    if s.type_name.endswith("[]"):
        if not isinstance(value, (list, tuple)):
            return f"must be a list ({s.type_name}), e.g. {_show(list(s.default))}"
        elem = s.type_name[:-2]
        for v in value:
            reason = _type_reason(elem, v)
            if reason:
                return f"every element {reason}"
        if s.rule.length is not None and len(value) != s.rule.length:
            return f"must have {s.rule.length} values, got {len(value)}"
        for v in value:
            reason = s.rule.element_reason(v)
            if reason:
                return f"every element {reason}" if len(value) > 1 else reason
        if s.rule.increasing and any(not b > a for a, b in zip(value, value[1:])):
            return "must be increasing ([min, max] with min < max)"
        return None
    reason = _type_reason(s.type_name, value)
    if reason:
        return reason
    return s.rule.element_reason(value)


def check_value(s: ParamSpec, value: Any, where: str = "") -> Optional[str]:
    """One line naming the parameter, the value and what is allowed; None if allowed."""
    reason = value_reason(s, value)
    if reason is None:
        return None
    return f"{where}{s.name} = {_show(value)}: {reason}"


def nearest(name: str, names: Iterable[str]) -> Optional[str]:
    """The closest valid name (difflib), for 'did you mean'."""
    names = list(names)
    match = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    if not match:  # a dotted name: compare the last part too (kernel.lenght_scale_m)
        tails = {n.rsplit(".", 1)[-1]: n for n in names}
        tail = difflib.get_close_matches(name.rsplit(".", 1)[-1], list(tails), n=1, cutoff=0.75)
        match = [tails[tail[0]]] if tail else []
    return match[0] if match else None


def unknown_text(kind: str, name: str, names: Iterable[str]) -> str:
    """``unknown parameter 'alhpa' (did you mean 'alpha'?)``."""
    names = sorted(names)
    guess = nearest(name, names)
    hint = f"did you mean '{guess}'?" if guess else f"known: {', '.join(names)}"
    return f"unknown {kind} '{name}' ({hint})"


def check_sections(
    sections: Mapping[str, Mapping[str, Any]],
    tables: Mapping[str, Mapping[str, Sequence[Any]]],
    where: str = "",
) -> list[str]:
    """Problems of one parameter file's ``{node or '/**': {name: value}}``.

    A node section may hold that node's parameters (and rclpy's own); the
    wildcard ``/**`` section names that some node knows, with a value every
    node that knows it accepts. Each problem is one line.
    """
    all_specs = {node: {**specs(ROS_BUILTIN), **specs(t)} for node, t in tables.items()}
    errors = []
    for node, values in sections.items():
        if node == "/**":
            for name, value in values.items():
                owners = [s[name] for s in all_specs.values() if name in s]
                if not owners:
                    known = set().union(*(s.keys() for s in all_specs.values()))
                    errors.append(f"{where}/**: {unknown_text('parameter', name, known)}")
                    continue
                for s in owners:
                    msg = check_value(s, value, f"{where}/**: ")
                    if msg:
                        errors.append(msg)
                        break
            continue
        if node not in all_specs:
            errors.append(f"{where}{unknown_text('node', node, all_specs)}")
            continue
        for name, value in values.items():
            if name not in all_specs[node]:
                errors.append(f"{where}{node}: {unknown_text('parameter', name, all_specs[node])}")
                continue
            msg = check_value(all_specs[node][name], value, f"{where}{node}.")
            if msg:
                errors.append(msg)
    return errors
