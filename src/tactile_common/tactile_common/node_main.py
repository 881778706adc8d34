"""The ``main()`` every node of the graph shares.

SIGINT and SIGTERM only *request* the end: their handler sets a flag that the
spin loop checks between callbacks (within 0.1 s). A callback is never cut in
the middle (Python's default SIGINT handler raises ``KeyboardInterrupt`` at any
bytecode: it once cut a recorder's MCAP write in half, and the file's last
chunk was corrupt). Then ``close()`` runs (e.g. the recorder finalises its
file), the node is destroyed and the context shut down.
"""

from __future__ import annotations

import signal
import sys
from typing import Callable, Optional, Sequence

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def run_node(
    make_node: Callable[[], Node],
    args: Optional[Sequence[str]] = None,
    executor: Optional[Callable[[], Executor]] = None,
) -> int:
    """Init rclpy, build the node, spin until SIGINT/SIGTERM, shut down.

    A node whose constructor raises ``ValueError`` or one of rclpy's parameter
    exceptions (bad parameters, a missing file) logs the message and exits
    with status 2, without a traceback.
    If the node has a ``close()`` method it is called before the node is
    destroyed, whatever ended the spin. A node that sets ``done = True``
    ends the spin itself (exit status 0, or the node's ``exit_status``).

    Returns:
        the process exit status.
    """
    rclpy.init(args=args if args is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    stop_requested: list[int] = []
    previous = {sig: signal.signal(sig, lambda signum, _frame: stop_requested.append(signum))
                for sig in STOP_SIGNALS}
    node = None
    status = 0
    try:
        try:
            node = make_node()
        except (ValueError, ParameterException) as exc:  # configuration errors: a message, not a traceback
            rclpy.logging.get_logger(getattr(make_node, "__name__", "node")).fatal(str(exc))
            return 2
        ex = executor() if executor is not None else SingleThreadedExecutor()
        ex.add_node(node)
        # A node that finishes its job by itself (e.g. the explorer) sets ``done``.
        while rclpy.ok() and not stop_requested and not getattr(node, "done", False):
            ex.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:  # the context was shut down outside the loop: a normal end
        pass
    except Exception:  # noqa: BLE001
        # A node may shut its own context down when its job is done (the player):
        # a wait or publish already under way then fails with an RCLError, a normal end.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            status = int(getattr(node, "exit_status", status))
            close = getattr(node, "close", None)
            if callable(close):
                close()
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return status
