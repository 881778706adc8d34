"""Read ROS 2 parameter files the way ``--params-file`` does, for ROS-free code.

The offline exploration loop must use exactly the parameters the nodes get,
so it reads the same YAML files: a file holds sections keyed by node name
(``soc_planner: ros__parameters: {...}``) and/or the wildcard ``/**``; later
files override earlier ones, and a node's own section overrides the wildcard.
Nested dictionaries are flattened to dotted names as ROS does.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml


class _RosYamlLoader(yaml.SafeLoader):
    """SafeLoader that reads numbers like ROS's parameter parser (YAML 1.2):
    ``2.0e7`` and ``1e-12`` are floats (PyYAML's YAML 1.1 rules make them strings)."""


_RosYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."),
)


def load_yaml(text: str):
    """Parse YAML text with ROS's number rules."""
    return yaml.load(text, Loader=_RosYamlLoader)


class ParamsFileError(ValueError):
    """A parameter file that cannot be read, with the file and the reason."""


def _flatten(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out


def read_params_file(path: Path) -> dict[str, dict[str, Any]]:
    """``{node name or '/**': {param: value}}`` of one file.

    Parsed once per file version (path, size, mtime): an experiment reads the
    same few files for every node, and PyYAML takes ~20 ms per file.
    """
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise ParamsFileError(f"{path}: no such parameter file") from None
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _CACHE:
        if len(_CACHE) > 256:
            _CACHE.clear()
        _CACHE[key] = _read_params_file(path)
    return copy.deepcopy(_CACHE[key])


_CACHE: dict[tuple, dict[str, dict[str, Any]]] = {}


def _read_params_file(path: Path) -> dict[str, dict[str, Any]]:
    try:
        doc = load_yaml(path.read_text())
    except FileNotFoundError:
        raise ParamsFileError(f"{path}: no such parameter file") from None
    except yaml.YAMLError as exc:
        raise ParamsFileError(f"{path}: not valid YAML: {exc}") from None
    if doc is None:
        return {}
    if not isinstance(doc, Mapping):
        raise ParamsFileError(f"{path}: expected 'node_name: ros__parameters: ...' sections")
    sections: dict[str, dict[str, Any]] = {}
    for node, body in doc.items():
        if not isinstance(body, Mapping) or "ros__parameters" not in body:
            raise ParamsFileError(f"{path}: section '{node}' has no 'ros__parameters'")
        key = "/**" if node == "/**" else str(node).lstrip("/")
        sections[key] = _flatten(body["ros__parameters"] or {})
    return sections


def node_params(paths: Iterable[Path], node_name: str) -> dict[str, Any]:
    """Parameters of ``node_name`` from ``paths`` (in order; later files win)."""
    merged: dict[str, Any] = {}
    for path in paths:
        sections = read_params_file(path)
        merged.update(sections.get("/**", {}))
        merged.update(sections.get(node_name, {}))
    return merged


def package_config(package: str, filename: str) -> Path:
    """``share/<package>/config/<filename>``: from the ament index when the
    package is installed (colcon or our venv), else from the source tree."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            path = Path(get_package_share_directory(package)) / "config" / filename
            if path.exists():
                return path
        except (PackageNotFoundError, KeyError, ValueError, OSError):  # OSError: no AMENT_PREFIX_PATH
            pass
    except ImportError:  # pragma: no cover - ament_index_python ships with rclpy
        pass
    import importlib.util

    spec = importlib.util.find_spec(package)
    if spec is None or spec.origin is None:
        raise ParamsFileError(f"package '{package}' is not installed")
    path = Path(spec.origin).resolve().parent.parent / "config" / filename
    if not path.exists():
        raise ParamsFileError(f"{package} has no config/{filename}")
    return path
