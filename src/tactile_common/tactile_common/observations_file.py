"""A run's observations as a CSV file: what a resumed run starts from.

One row per observation, the fields of :data:`tactile_common.fields.CONTACT_DTYPE`
in that order (world frame, metres, unit outward normal, newtons, label 1
contact / 0 free space), written with 17 significant digits so that a float64
reads back bit for bit: an estimator fed the file holds exactly the estimate
fed the original messages.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .fields import CONTACT_DTYPE, LABEL_CONTACT, LABEL_FREE_SPACE

HEADER = ",".join(CONTACT_DTYPE.names)


def write_observations(path: str | Path, observations: np.ndarray) -> Path:
    """Write a CONTACT_DTYPE array (any length, also 0) as CSV; returns the path."""
    path = Path(path)
    obs = np.asarray(observations, dtype=CONTACT_DTYPE).reshape(-1)
    with open(path, "w") as fh:
        fh.write(HEADER + "\n")
        for row in obs.tolist():
            fh.write(",".join(f"{v:.17g}" for v in row[:-1]) + f",{int(row[-1])}\n")
    return path


def read_observations(path: str | Path) -> np.ndarray:
    """The observations of a file written by :func:`write_observations`.

    Raises ``ValueError`` with one line naming the file and the problem (missing file,
    another header, a row that is not numbers, non-finite positions, unknown labels).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read observations ({exc.strerror or exc})") from None
    lines = text.splitlines()
    if not lines or lines[0].strip() != HEADER:
        raise ValueError(f"{path}: not an observations file (its first line must be '{HEADER}')")
    if len(lines) == 1:
        return np.zeros(0, dtype=CONTACT_DTYPE)
    try:
        table = np.loadtxt(io.StringIO("\n".join(lines[1:])), delimiter=",", ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{path}: unreadable row ({exc})") from None
    if table.shape[1] != len(CONTACT_DTYPE.names):
        raise ValueError(f"{path}: rows have {table.shape[1]} columns, expected {len(CONTACT_DTYPE.names)}")
    labels = table[:, -1]
    if not np.isin(labels, (LABEL_CONTACT, LABEL_FREE_SPACE)).all():
        raise ValueError(f"{path}: labels must be {LABEL_CONTACT} (contact) or {LABEL_FREE_SPACE} (free space)")
    if not np.isfinite(table[:, :3]).all():
        raise ValueError(f"{path}: a position is not finite")
    obs = np.zeros(len(table), dtype=CONTACT_DTYPE)
    for i, name in enumerate(CONTACT_DTYPE.names):
        obs[name] = table[:, i]
    return obs
