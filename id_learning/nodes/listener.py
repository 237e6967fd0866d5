"""An in-process listener of a namespace's reference, tau_u and /diagnostics.

The online check (``id_learning.online_check``) and the benchmarks start this package's nodes as
processes (``nodes.process``) and watch what they publish through a ``Listener``: an rclpy node
in its own context and DDS domain, spun by a thread of this process, that keeps every message
in arrival order. Waits are on its condition, with deadlines.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from id_learning.nodes.msg_conversions import time_to_ns
from id_learning.nodes.qos import DIAGNOSTICS_QOS, reference_qos
from id_learning.nodes.runtime import close_spun_node

__all__ = ['LISTEN_DEPTH', 'Listener']

#: Listener queue depth [messages]: a whole second of stalls at 125 Hz.
LISTEN_DEPTH = 1000


class Listener:
    """An rclpy node in this process, spun by a thread: reference, tau_u and diagnostics.

    Args:
        domain_id: the DDS domain of the nodes listened to.
        namespace: the namespace of the ``reference`` and ``tau_u`` topics and of
            ``diagnostics`` (relative names: a node's /diagnostics remapped into it).
    """

    def __init__(self, domain_id: int, namespace: str) -> None:
        self.condition = threading.Condition()
        # (stamp [ns], names, q, v, a) and (stamp [ns], names, tau), in arrival order.
        self.references: list[
            tuple[int, tuple[str, ...], list[float], list[float], list[float]]
        ] = []
        self.outputs: list[tuple[int, tuple[str, ...], list[float]]] = []
        self.diagnostics: dict[str, dict[str, str]] = {}
        self.diagnostics_count: dict[str, int] = {}
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        try:
            self.node = rclpy.create_node(
                'online_check_listener', namespace=namespace, context=self.context
            )
            self.executor = SingleThreadedExecutor(context=self.context)
            self.executor.add_node(self.node)
            depth = reference_qos(LISTEN_DEPTH)
            self.node.create_subscription(JointTrajectory, 'reference', self._on_reference, depth)
            self.node.create_subscription(JointState, 'tau_u', self._on_tau_u, depth)
            self.node.create_subscription(
                DiagnosticArray, 'diagnostics', self._on_diagnostics, DIAGNOSTICS_QOS
            )
        except Exception:
            self.context.try_shutdown()
            raise
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='online_check', daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_reference(self, msg: Any) -> None:
        point = msg.points[0]
        item = (
            time_to_ns(msg.header.stamp),
            tuple(msg.joint_names),
            list(point.positions),
            list(point.velocities),
            list(point.accelerations),
        )
        with self.condition:
            self.references.append(item)
            self.condition.notify_all()

    def _on_tau_u(self, msg: Any) -> None:
        item = (time_to_ns(msg.header.stamp), tuple(msg.name), list(msg.effort))
        with self.condition:
            self.outputs.append(item)
            self.condition.notify_all()

    def _on_diagnostics(self, msg: Any) -> None:
        with self.condition:
            for status in msg.status:
                self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}
                self.diagnostics_count[status.name] = (
                    self.diagnostics_count.get(status.name, 0) + 1
                )
            self.condition.notify_all()

    def status(self, name: str) -> dict[str, str]:
        """The last /diagnostics values of the status ``name`` (empty before the first)."""
        return self.diagnostics.get(name, {})

    def wait(
        self,
        predicate: Callable[[], bool],
        timeout: float,
        give_up: Callable[[], bool] = lambda: False,
    ) -> bool:
        """Wait for ``predicate()``: True once it holds, False at the timeout [s] or ``give_up()``.

        Both are called with the condition held, at every message and at least every 0.1 s.
        """
        deadline = time.monotonic() + timeout
        with self.condition:
            while not predicate():
                left = deadline - time.monotonic()
                if give_up() or left <= 0:
                    return False
                self.condition.wait(min(left, 0.1))
        return True

    def close(self) -> None:
        """Stop spinning and shut the node and its context down."""
        close_spun_node(self.node, self.executor, self._thread, self._stop)
