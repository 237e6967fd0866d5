"""Waiting on what a node process logs (its log is a file: polled, with a deadline)."""

from __future__ import annotations

import time

from ros.ros_helpers import STARTUP_S

from id_learning.nodes.process import NodeProcess


def wait_for_log(node: NodeProcess, text: str, timeout: float = STARTUP_S) -> None:
    """Wait until the node's log holds ``text``; fails when the node ends first or time is up."""
    deadline = time.monotonic() + timeout
    while text not in node.log():
        assert node.is_running, node.log()
        assert time.monotonic() < deadline, f'no {text!r} in the log after {timeout:g} s'
        time.sleep(0.1)
