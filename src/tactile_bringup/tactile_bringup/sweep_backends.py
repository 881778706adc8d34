"""Where a sweep's runs execute: a local process pool (default) or a Dask cluster.

Both take the same jobs and worker and yield ``(job, result)`` in the order runs
finish, where ``result`` is the worker's report or a failure record of
:func:`tactile_bringup.sweep.guarded` (a run that raises, or on a cluster a
worker that died with it, is a failure, and the sweep goes on).

A Dask cluster (``tactile-benchmark --cluster tcp://HOST:8786``) is any
``distributed`` scheduler whose workers run this project's code in the same
version: before the first job the workers' code fingerprint (a hash of every
``tactile_*`` module) is compared with ours, and a worker with other code stops
the sweep with one line naming it (a worker that joins later is not checked:
start the workers first). Parameter files travel inside the jobs, so
the workers need no shared disk. Start workers with one thread each and one
BLAS thread (``OPENBLAS_NUM_THREADS=1 dask worker tcp://HOST:8786 --nthreads 1
--nworkers N``): a run is single-threaded numpy, and BLAS threads on top of
N runs oversubscribe the cores.
"""

from __future__ import annotations

import hashlib
import importlib
import multiprocessing as mp
import os
import re
from functools import partial
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence

from .sweep import failure_record, guarded

#: packages whose source makes the code fingerprint
CODE_PACKAGES = ("tactile_common", "tactile_gpis", "tactile_planner", "tactile_driver", "tactile_sim", "tactile_bringup")

_ADDRESS = re.compile(r"^(?:(tcp|tls)://)?(\[[0-9a-fA-F:]+\]|[A-Za-z0-9.\-]+):(\d{1,5})$")


class ClusterError(ValueError):
    """The cluster cannot run the sweep (unreachable, no workers, other code); one line says why."""


def code_fingerprint() -> str:
    """sha256 (16 hex digits) over the path and bytes of every ``.py`` file of :data:`CODE_PACKAGES`."""
    h = hashlib.sha256()
    for name in CODE_PACKAGES:
        root = Path(importlib.import_module(name).__file__).parent
        for path in sorted(root.rglob("*.py")):
            h.update(f"{name}/{path.relative_to(root).as_posix()}\0".encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _worker_fingerprint() -> str:
    """:func:`code_fingerprint` as a worker computes it (sent by reference: the worker's own code)."""
    return code_fingerprint()


def cluster_address(text: str) -> str:
    """``HOST:PORT`` or ``tcp://HOST:PORT`` (also ``tls://``) → the scheduler address with its scheme."""
    m = _ADDRESS.match(text.strip())
    if not m or not 0 < int(m.group(3)) < 65536:
        raise ClusterError(f"--cluster {text}: not a scheduler address (HOST:PORT or tcp://HOST:PORT, "
                           "e.g. tcp://127.0.0.1:8786)")
    return f"{m.group(1) or 'tcp'}://{m.group(2)}:{m.group(3)}"


def local_pool(jobs: Sequence[dict], worker: Callable[[dict], dict], processes: int) -> Iterator[tuple[dict, dict]]:
    """Run the jobs on ``processes`` spawned processes of this machine, one BLAS thread each."""
    # BLAS reads these when it loads, so the workers are spawned, not forked; N runs on N
    # cores with BLAS's own threads on top doubled the wall time per run (measured, 3D).
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    by_index = dict(enumerate(jobs))
    with mp.get_context("spawn").Pool(processes, maxtasksperchild=4) as pool:
        for index, result in pool.imap_unordered(partial(_indexed, worker), list(by_index.items())):
            yield by_index[index], result


def _indexed(worker: Callable[[dict], dict], item: tuple[int, dict]) -> tuple[int, dict]:
    index, job = item
    return index, guarded(worker, job)


def dask_cluster(jobs: Sequence[dict], worker: Callable[[dict], dict], address: str,
                 connect_timeout_s: float = 10.0, worker_wait_s: float = 30.0,
                 on_ready: Optional[Callable[[str], None]] = None) -> Iterator[tuple[dict, dict]]:
    """Run the jobs on the Dask scheduler at ``address`` (see the module docstring).

    Raises:
        ClusterError: the scheduler cannot be reached within ``connect_timeout_s``, no worker
            joins within ``worker_wait_s``, or a worker runs other code.
    """
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - a pinned dependency of the project
        raise ClusterError(f"--cluster needs the 'distributed' package ({exc}); run scripts/setup.sh") from None
    address = cluster_address(address)
    try:
        client = Client(address, timeout=f"{connect_timeout_s}s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ClusterError(f"--cluster {address}: cannot reach the Dask scheduler within "
                           f"{connect_timeout_s:g} s ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
    futures: list = []
    try:
        try:
            client.wait_for_workers(1, timeout=worker_wait_s)
        except (TimeoutError, OSError):
            raise ClusterError(f"--cluster {address}: no worker joined the scheduler within {worker_wait_s:g} s") from None
        ours = code_fingerprint()
        theirs = client.run(_worker_fingerprint)
        other = sorted(w for w, fp in theirs.items() if fp != ours)
        if other:
            raise ClusterError(f"--cluster {address}: worker(s) {', '.join(other)} run other code than this tree "
                               f"(fingerprint {theirs[other[0]]} against {ours}): install this tree on them")
        if on_ready is not None:
            threads = sum(client.nthreads().values())
            on_ready(f"on the Dask cluster at {address}: {len(theirs)} workers, {threads} threads")
        futures = client.map(partial(guarded, worker), list(jobs), pure=False)
        job_of = {f.key: j for f, j in zip(futures, jobs)}
        for fut in as_completed(futures, loop=client.loop):
            job = job_of[fut.key]
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker that died with the run (KilledWorker) etc.
                result = failure_record(job, exc)
            yield job, result
    finally:
        if futures:
            client.cancel(futures)
        client.close()
