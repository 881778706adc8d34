"""Full ``ros2msg`` message definitions, built the way rosbag2 builds them.

rosbag2 (``LocalMessageDefinitionSource``) stores in each MCAP schema the
root type's ``.msg`` text followed, for each dependency in depth-first order
(dependencies of one type visited in sorted order, each type once), by a line
of 80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text. The
``.msg`` files come from ``<prefix>/share/<pkg>/msg/`` of an ament prefix
(``AMENT_PREFIX_PATH``, else the running virtualenv).

ROS-free: no rclpy, no message packages.
"""

from __future__ import annotations

import os
import re
import sys
from functools import lru_cache
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

SEPARATOR = "=" * 80 + "\n"

# The first token of each non-comment line (rosbag2's MSG_FIELD_TYPE_REGEX).
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16",
    "uint16", "int32", "uint32", "int64", "uint64", "string",
})
_NAME = r"[a-zA-Z][a-zA-Z0-9_]*"
_TYPE_NAME = re.compile(rf"^({_NAME})/(?:({_NAME})/)?({_NAME})$")
_MAX_DEPTH = 50


class DefinitionNotFound(LookupError):
    """No ``.msg`` file for a type on the search path; the message names the paths tried."""


def split_type_name(type_name: str) -> Tuple[str, str, str]:
    """``pkg/msg/Type`` or ``pkg/Type`` -> (package, namespace, Type)."""
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(f"invalid message type name '{type_name}' (expected pkg/msg/Type)")
    package, namespace, name = match.groups()
    return package, namespace or "msg", name


def share_prefixes() -> List[Path]:
    """Ament prefixes searched for ``share/<pkg>/msg``: AMENT_PREFIX_PATH, then sys.prefix."""
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for extra in (os.environ.get("VIRTUAL_ENV"), sys.prefix):
        if extra and Path(extra) not in prefixes:
            prefixes.append(Path(extra))
    return prefixes


@lru_cache(maxsize=None)
def _read_msg(type_name: str, prefixes: Tuple[Path, ...]) -> str:
    package, namespace, name = split_type_name(type_name)
    tried = []
    for prefix in prefixes:
        path = prefix / "share" / package / namespace / f"{name}.msg"
        if path.is_file():
            return path.read_text()
        tried.append(str(path))
    raise DefinitionNotFound(f"no .msg definition for '{type_name}' (tried: {', '.join(tried)})")


def msg_dependencies(text: str, package: str) -> List[str]:
    """Non-primitive field types of a ``.msg`` text as ``pkg/Type``, sorted, unique."""
    deps = set()
    for match in _FIELD_TYPE.finditer(text):
        token = match.group(1)
        if token in _PRIMITIVES:
            continue
        deps.add(token if "/" in token else f"{package}/{token}")
    return sorted(deps)


def full_definition(type_name: str, prefixes: Optional[Sequence[Path]] = None) -> str:
    """The complete ``ros2msg`` schema text of ``type_name`` (e.g. ``std_msgs/msg/String``).

    Raises:
        DefinitionNotFound: a type or one of its dependencies has no ``.msg`` file.
        ValueError: the type name is malformed or the nesting is too deep.
    """
    search = tuple(prefixes) if prefixes is not None else tuple(share_prefixes())
    seen: set = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise ValueError(f"message definition of '{type_name}' nests too deep")
        text = _read_msg(name, search)
        out = [text]
        for dep in msg_dependencies(text, split_type_name(name)[0]):
            if dep not in seen:
                seen.add(dep)
                out.append("\n" + SEPARATOR + f"MSG: {dep}\n" + append(dep, depth - 1))
        return "".join(out)

    return append(type_name, _MAX_DEPTH)
