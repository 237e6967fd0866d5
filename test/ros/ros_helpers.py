"""Node processes and an in-test listener for the ROS tests (real DDS over loopback).

Every node runs in its own process (``python -m id_learning.nodes.<name> --ros-args ...``) with
the whole environment (the wheels' .pth bootstrap needs LD_LIBRARY_PATH) plus the test's own
ROS_DOMAIN_ID. Synchronisation is by conditions with deadlines, never by sleeping.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import subprocess
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from support import REPO

from id_learning.nodes.process import NodeProcess
from id_learning.nodes.runtime import close_spun_node

#: Deadline of a wait on a node that has to start first (imports torch on a loaded machine).
STARTUP_S = 90.0


def node_environment(domain_id: int) -> dict[str, str]:
    """The test process's environment for a child node, in the given DDS domain."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    env['PYTHONUNBUFFERED'] = '1'
    # Children run from the checkout, whatever the working directory.
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO), env.get('PYTHONPATH')]))
    return env


def random_domain() -> int:
    """A DDS domain for one test, below the ports Linux hands out as ephemeral (ids <= 101)."""
    return random.SystemRandom().randint(1, 101)


@contextlib.contextmanager
def node_processes(tmp_path: Path, domain_id: int) -> Iterator[Callable[..., NodeProcess]]:
    """Start nodes with ``start(module, parameters, name=..., remaps=...)``; all are stopped on
    exit, even on failure, and their logs printed (pytest shows them for a failing test)."""
    started: list[NodeProcess] = []
    env = node_environment(domain_id)

    def start(
        module: str,
        parameters: dict[str, Any],
        *,
        name: str | None = None,
        remaps: dict[str, str] | None = None,
    ) -> NodeProcess:
        log_path = tmp_path / f'{name or module}.log'
        node = NodeProcess(module, parameters, log_path, env, remaps)
        started.append(node)
        return node

    try:
        yield start
    finally:
        for node in started:  # all at once: each needs a moment to close
            node.interrupt()
        for node in started:
            node.stop()
        for node in started:
            print(f'----- {node.log_path.name} (exit {node.process.returncode}) -----')
            print(node.log())
        if any(node.was_killed for node in started):
            clean_shared_memory()


def clean_shared_memory() -> None:
    """Remove the Fast DDS shared-memory files a killed process left in /dev/shm."""
    fastdds = shutil.which('fastdds') or str(Path(sys.executable).parent / 'fastdds')
    if Path(fastdds).exists():
        subprocess.run([fastdds, 'shm', 'clean'], capture_output=True, timeout=60, check=False)


class Listener:
    """An rclpy node in the test process, spun by a thread; collects messages per topic."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('test_listener', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.condition = threading.Condition()
        self.messages: dict[str, list[Any]] = defaultdict(list)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def subscribe(self, msg_type: type, topic: str, qos: Any = 100) -> None:
        def store(msg: Any) -> None:
            with self.condition:
                self.messages[topic].append(msg)
                self.condition.notify_all()

        self.node.create_subscription(msg_type, topic, store, qos)

    def wait_for(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        """Wait until predicate() holds (checked on every message and every 50 ms)."""
        deadline = time.monotonic() + timeout
        with self.condition:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f'timed out after {timeout:g} s waiting for {what}')
                self.condition.wait(min(left, 0.05))

    def wait_for_subscribers(self, topic: str, count: int, timeout: float = STARTUP_S) -> None:
        """Wait until the graph shows ``count`` subscriptions on a topic."""
        self.wait_for(
            lambda: self.node.count_subscribers(topic) >= count,
            timeout,
            f'{count} subscription(s) on {topic}',
        )

    def publishers_subscribed(
        self, msg_type: type, topics: Any, qos: Any, what: str = 'the recorder to subscribe'
    ) -> dict[str, Any]:
        """A publisher per topic, returned once each has a subscriber (``what`` waited for)."""
        publishers = {topic: self.node.create_publisher(msg_type, topic, qos) for topic in topics}
        self.wait_for(
            lambda: all(p.get_subscription_count() >= 1 for p in publishers.values()),
            STARTUP_S,
            what,
        )
        return publishers

    def diagnostics(self, name: str) -> dict[str, str] | None:
        """The key-values of the latest /diagnostics status with this name."""
        for msg in reversed(self.messages['/diagnostics']):
            for status in msg.status:
                if status.name == name:
                    return {item.key: item.value for item in status.values}
        return None

    def close(self) -> None:
        close_spun_node(self.node, self.executor, self._thread, self._stop)
