"""run_node: SIGINT/SIGTERM end a node between callbacks, never inside one, and close() runs."""

import os
import signal
import subprocess
import sys
import time

import pytest

from tactile_common.testing import DomainLease

NODE = r'''
import sys, time
from rclpy.node import Node
from tactile_common.node_main import run_node

LOG = open(sys.argv[1], "a", buffering=1)

class Busy(Node):
    """A timer callback that takes 1 s: a signal will arrive while it runs."""
    def __init__(self):
        super().__init__("busy")
        self.create_timer(0.05, self.work)
    def work(self):
        LOG.write("start\n")
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            sum(range(1000))
        LOG.write("end\n")
    def close(self):
        LOG.write("close\n")

sys.exit(run_node(Busy, ["busy"]))
'''


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_a_callback_lets_it_finish_then_closes(tmp_path, sig):
    lease = DomainLease()
    try:
        env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id))
        env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        log = tmp_path / "events.txt"
        proc = subprocess.Popen([sys.executable, "-c", NODE, str(log)], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 30
        while not (log.exists() and "start" in log.read_text()):  # inside the first callback
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[0]
            time.sleep(0.01)
        proc.send_signal(sig)
        output, _ = proc.communicate(timeout=20)
        assert proc.returncode == 0, output
        assert "Traceback" not in output, output
        assert log.read_text().split() == ["start", "end", "close"]  # finished, no new callback, closed
    finally:
        lease.release()
