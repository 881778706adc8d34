"""Harness for graph tests: node processes on a private ROS domain, waits with timeouts.

Usage (see ``tests/conftest.py`` for the ``ros_graph`` fixture)::

    graph.start("talker", ["tactile-smoke-talker", "--ros-args", "-p", "rate_hz:=20.0"])
    msg = graph.wait_for_message("/chatter", PointCloud2, qos.EVENTS, timeout_s=20)

Every process gets ``ROS_DOMAIN_ID`` = the graph's own domain (one per test,
held with a file lock so concurrent test runs never share one) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless the caller set another
value. Processes run in their own session; ``stop_all`` sends SIGINT, then
SIGTERM, then SIGKILL to the whole group, so nothing is left behind.
"""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

#: Domains handed to tests (the scripts' default domain, 42, is excluded).
TEST_DOMAINS = [d for d in range(10, 100) if d != 42]
_LOCK_DIR = Path(tempfile.gettempdir()) / "tactile_ros_domains"


class GraphTestError(AssertionError):
    """A wait timed out or a node process died; the message says which."""


class Received(list):
    """Messages a test subscription has received, plus its matched writers.

    DDS matches each writer to each reader on its own: seeing messages from one
    node says nothing about another node's writer on a different topic. A test
    that expects a one-off message waits on ``publishers`` first, so the
    message cannot be published before the test's reader is matched (and lost).
    """

    def __init__(self) -> None:
        super().__init__()
        self.subscription = None

    @property
    def publishers(self) -> int:
        """Writers matched to this subscription now."""
        return self.subscription.get_publisher_count()


def status_of(name_prefix: str) -> Callable[[Any], bool]:
    """A ``keep`` for :meth:`RosGraph.collect` on /diagnostics: the arrays whose first status is the named node's."""
    return lambda msg: bool(msg.status) and msg.status[0].name.startswith(name_prefix)


def device_hears_poses(device_diags: Sequence[Any], max_lag_s: float = 0.1) -> bool:
    """``sim_sensor_device`` has read fingertip poses and is up to date with them (its last status)."""
    if not device_diags:
        return False
    v = {kv.key: kv.value for kv in device_diags[-1].status[0].values}
    return int(v["poses"]) > 0 and float(v["pose_lag_s"]) < max_lag_s


def wait_for_pose_readers(graph: "RosGraph", pose_pub: Any, contacts: "Received", device_diags: Sequence[Any],
                          timeout_s: float = 20.0) -> None:
    """A bench script's pose stream is heard: ``sim_sensor_device`` and ``tactile_sensor`` subscribe to
    ``pose_pub``, the test hears the driver's ``contacts``, and the device reads the poses up to date.

    The subscription count is this end's view; the device may hear the poses seconds later (then their
    backlog), and an approach before that would be sensed at the device's far default pose, then deep.
    """
    graph.wait_for(lambda: pose_pub.get_subscription_count() >= 2 and contacts.publishers, timeout_s,
                   "pose subscribers and the contact writer")
    graph.wait_for(lambda: device_hears_poses(device_diags), timeout_s, "the device reading the poses")


class DomainLease:
    """Exclusive use of one ROS_DOMAIN_ID across processes (a file lock)."""

    def __init__(self) -> None:
        _LOCK_DIR.mkdir(parents=True, exist_ok=True)
        start = os.getpid() % len(TEST_DOMAINS)
        for i in range(len(TEST_DOMAINS)):
            domain = TEST_DOMAINS[(start + i) % len(TEST_DOMAINS)]
            fh = open(_LOCK_DIR / f"{domain}.lock", "w")
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                fh.close()
                continue
            self.domain_id = domain
            self._fh = fh
            return
        raise GraphTestError("no free ROS_DOMAIN_ID for the test")

    def release(self) -> None:
        fcntl.flock(self._fh, fcntl.LOCK_UN)
        self._fh.close()


def graph_env(domain_id: int, extra: Optional[dict] = None) -> dict:
    """Environment for a node process on ``domain_id``, discovery on localhost."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    venv = os.environ.get("VIRTUAL_ENV")
    if venv and venv not in env.get("AMENT_PREFIX_PATH", ""):
        env["AMENT_PREFIX_PATH"] = ":".join(filter(None, [venv, env.get("AMENT_PREFIX_PATH")]))
    if extra:
        env.update(extra)
    return env


class NodeProcess:
    """One node process with its log file."""

    def __init__(self, name: str, cmd: Sequence[str], env: dict, log_dir: Path) -> None:
        self.name = name
        self.cmd = list(cmd)
        self.log_path = log_dir / f"{name}.log"
        self._log = open(self.log_path, "wb")
        self.popen = subprocess.Popen(
            self.cmd, env=env, stdout=self._log, stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL, start_new_session=True,
        )

    def alive(self) -> bool:
        return self.popen.poll() is None

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, timeout_s: float = 10.0) -> Optional[int]:
        """SIGINT, then SIGTERM, then SIGKILL to the process group; the exit code."""
        for sig, wait_s in ((signal.SIGINT, timeout_s), (signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
            if self.popen.poll() is not None:
                break
            try:
                os.killpg(self.popen.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.popen.wait(wait_s)
            except subprocess.TimeoutExpired:
                continue
        try:  # children that outlived the leader
            os.killpg(self.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self._log.close()
        return self.popen.returncode


class RosGraph:
    """Node processes plus an in-test rclpy node, all on one private domain."""

    def __init__(self, domain_id: int, log_dir: Path) -> None:
        self.domain_id = domain_id
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: dict[str, NodeProcess] = {}
        self._context: Optional[Context] = None
        self._node: Optional[Node] = None
        self._executor: Optional[SingleThreadedExecutor] = None

    # -- processes -----------------------------------------------------------
    def start(self, name: str, cmd: Sequence[str], env: Optional[dict] = None) -> NodeProcess:
        """Start ``cmd`` as a node process on this graph's domain."""
        if name in self.procs:
            raise ValueError(f"process name '{name}' already used")
        proc = NodeProcess(name, cmd, graph_env(self.domain_id, env), self.log_dir)
        self.procs[name] = proc
        return proc

    def env(self, extra: Optional[dict] = None) -> dict:
        """The environment node processes of this graph get (for other subprocesses)."""
        return graph_env(self.domain_id, extra)

    def logs(self) -> str:
        return "\n".join(
            f"----- {name} (exit {p.popen.poll()}) -----\n{p.log()}" for name, p in self.procs.items()
        )

    def stop_all(self) -> dict:
        """Stop every process (SIGINT first); their exit codes by name."""
        return {name: p.stop() for name, p in reversed(list(self.procs.items()))}

    # -- the test's own node -------------------------------------------------
    @property
    def node(self) -> Node:
        """An rclpy node in a private context on this graph's domain."""
        if self._node is None:
            self._context = Context()
            rclpy.init(context=self._context, domain_id=self.domain_id)
            self._node = rclpy.create_node(f"test_probe_{os.getpid()}", context=self._context)
            self._executor = SingleThreadedExecutor(context=self._context)
            self._executor.add_node(self._node)
        return self._node

    def spin_once(self, timeout_s: float = 0.05) -> None:
        self.node  # noqa: B018 (create on first use)
        self._executor.spin_once(timeout_sec=timeout_s)

    def wait_for(self, predicate: Callable[[], Any], timeout_s: float, what: str = "condition") -> Any:
        """Spin the test node until ``predicate()`` is truthy; return its value.

        Fails early, with the logs, if a node process has exited.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            value = predicate()
            if value:
                return value
            dead = [n for n, p in self.procs.items() if not p.alive()]
            if dead:
                raise GraphTestError(f"while waiting for {what}: process(es) {dead} exited\n{self.logs()}")
            if time.monotonic() > deadline:
                raise GraphTestError(f"timed out after {timeout_s:.0f} s waiting for {what}\n{self.logs()}")
            self.spin_once(0.05)

    def call(self, srv_type: Any, service: str, request: Any, timeout_s: float, what: str,
             answer_within_s: float = 5.0) -> Any:
        """Call ``service`` and return its response; resend if no answer came in ``answer_within_s``.

        Only for idempotent requests. ``service_is_ready`` sees the server's request reader; the
        server's response writer may not have matched this client's response reader yet, and
        Fast DDS then drops the response after 100 ms ("client will not receive response",
        ros2/rmw_fastrtps#467). A resend after matching is answered.
        """
        client = self.node.create_client(srv_type, service)
        try:
            deadline = time.monotonic() + timeout_s
            self.wait_for(client.service_is_ready, timeout_s, f"the service {service}")
            while True:
                future = client.call_async(request)
                try_s = min(answer_within_s, max(0.1, deadline - time.monotonic()))
                try:
                    self.wait_for(future.done, try_s, what)
                    return future.result()
                except GraphTestError:
                    client.remove_pending_request(future)
                    if time.monotonic() >= deadline or not all(p.alive() for p in self.procs.values()):
                        raise
        finally:
            self.node.destroy_client(client)

    def observe(self, duration_s: float, what: str) -> None:
        """Spin for ``duration_s`` while something must *not* happen (no trajectory in a dry run).

        Never a synchronisation: to wait for something to happen, use :meth:`wait_for`.
        Fails early, with the logs, if a node process exits.
        """
        end = time.monotonic() + duration_s
        self.wait_for(lambda: time.monotonic() >= end, duration_s + 5.0, f"{duration_s:g} s of {what}")

    def collect(self, topic: str, msg_type: Any, qos: QoSProfile, raw: bool = False,
                keep: Optional[Callable[[Any], bool]] = None) -> Received:
        """Subscribe now; the returned list fills with messages (those ``keep`` accepts) as the test spins."""
        received = Received()

        def on_message(msg: Any) -> None:
            if keep is None or keep(msg):
                received.append(msg)

        received.subscription = self.node.create_subscription(msg_type, topic, on_message, qos, raw=raw)
        return received

    def wait_for_message(
        self,
        topic: str,
        msg_type: Any,
        qos: QoSProfile,
        timeout_s: float,
        predicate: Optional[Callable[[Any], bool]] = None,
    ) -> Any:
        """The first message on ``topic`` (that satisfies ``predicate``)."""
        received = self.collect(topic, msg_type, qos)

        def first():
            for m in received:
                if predicate is None or predicate(m):
                    return m
            return None

        return self.wait_for(first, timeout_s, f"a message on {topic}")

    def close(self) -> dict:
        codes = self.stop_all()
        if self._node is not None:
            self._executor.shutdown()
            self._node.destroy_node()
            rclpy.try_shutdown(context=self._context)
            self._node = None
        return codes


class BusyCores:
    """A load generator: ``n`` processes that spin on the CPU (at normal priority) until closed.

    Use as a context manager around a graph run whose result must not depend on timing: on a
    2-core machine, two of them leave the graph half the CPU it had.
    """

    def __init__(self, n: int = 2) -> None:
        self.n = int(n)
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> "BusyCores":
        code = "while True:\n    pass\n"
        self.procs = [subprocess.Popen(["python3", "-c", code], stdin=subprocess.DEVNULL,
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                      for _ in range(self.n)]
        return self

    def __exit__(self, *exc: Any) -> None:
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait(timeout=10)
        self.procs = []
