"""The files a user keeps from a run, written next to ``report.json`` (docs/recording.md, "Exports").

World frame, metres:

- the estimated shape: ``shape.csv`` (contour), ``shape.ply`` and ``shape.obj``
  (polyline at the section height) in 2D; ``shape.ply`` (mesh with the GP posterior
  variance per vertex), ``shape.stl`` and ``shape.obj`` in 3D;
- ``contacts.ply``: every observation the estimate took (x y z nx ny nz label;
  label 1 contact, 0 free space);
- ``estimate.json``: the estimate's state (:mod:`tactile_gpis.state`), which
  ``tactile-explore-offline --load-state`` and ``replay.sh estimate.json --offline``
  load.

The offline loop, the explorer node (at the end of a run and on Ctrl-C) and the
re-analysis all write them through :func:`tactile_bringup.progress.write_outputs`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Mapping, Optional

from tactile_gpis.state import save_state

_LOG = logging.getLogger("tactile_bringup.exports")

#: shape files per mode
SHAPE_FILES = {"2d": ("shape.csv", "shape.ply", "shape.obj"), "3d": ("shape.ply", "shape.stl", "shape.obj")}
CONTACTS_FILE = "contacts.ply"
STATE_FILE = "estimate.json"


def run_description(report: Mapping[str, Any]) -> dict[str, Any]:
    """What the state file records of the run that built the estimate (from its report)."""
    keep = ("object", "mode", "strategy", "seed", "config")
    run = {k: report[k] for k in keep if k in report}
    s = report.get("summary") or {}
    run.update({k: s.get(k) for k in ("touches", "travel_m", "time_s", "final_iou", "stopped_because")})
    return run


def write_exports(estimator, out_dir: Path, mode: str, run: Optional[Mapping[str, Any]] = None) -> list[str]:
    """The shape files (if the estimate has a surface), contacts.ply and estimate.json into
    ``out_dir``; returns the paths written. A file that cannot be written is logged and
    skipped (the others, and the report written before, are kept)."""
    out_dir = Path(out_dir)
    jobs = [(out_dir / name, estimator.export_shape) for name in SHAPE_FILES[mode]] \
        if len(estimator.level_set().vertices) else []
    jobs += [(out_dir / CONTACTS_FILE, estimator.export_observations),
             (out_dir / STATE_FILE, lambda p: save_state(estimator, p, run))]
    written = []
    for path, write in jobs:
        try:
            write(path)
        except (OSError, ValueError) as exc:
            _LOG.error("%s not written: %s", path.name, exc)
            continue
        written.append(str(path))
    return written
