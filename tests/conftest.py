"""Shared pytest fixtures: the graph harness with a private ROS domain per test."""

from __future__ import annotations

import os

import pytest

# Discovery never leaves this host, whatever the caller's shell had (unless the
# user chose a value explicitly).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.pop("ROS_LOCALHOST_ONLY", None)


@pytest.fixture
def ros_graph(tmp_path):
    """A :class:`tactile_common.testing.RosGraph` on its own ROS_DOMAIN_ID.

    Every process it started is stopped at teardown; their logs are printed
    (pytest shows them when the test failed).
    """
    from tactile_common.testing import DomainLease, RosGraph

    lease = DomainLease()
    graph = RosGraph(lease.domain_id, tmp_path / "logs")
    try:
        yield graph
    finally:
        codes = graph.close()
        print(f"ROS_DOMAIN_ID={lease.domain_id} exit codes: {codes}")
        print(graph.logs())
        lease.release()


@pytest.fixture
def domain_env():
    """The environment for a script that starts a whole graph (scripts/explore.sh), on a private
    ROS_DOMAIN_ID with localhost-only discovery; the domain is held for the test's duration."""
    from tactile_common.testing import DomainLease

    lease = DomainLease()
    env = dict(os.environ, ROS_DOMAIN_ID=str(lease.domain_id))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    try:
        yield env
    finally:
        lease.release()
