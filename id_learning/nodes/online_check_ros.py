"""The online check's ROS side: the node processes, the in-process listener and the replay run.

The predictor and replay nodes run as separate processes (``NodeProcess``) in a private
namespace; this process listens to the reference, tau_u and /diagnostics through its own rclpy
context (imported only when a listener is made). ``start_predictor`` and ``replay_and_collect``
are the check's launch and wait steps; what they return is compared offline afterwards.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import id_learning
from id_learning.nodes.online_check_plan import CheckSetup, Excerpt
from id_learning.nodes.online_check_result import NS_PER_S, OnlineCheckError
from id_learning.nodes.process import NodeProcess
from id_learning.nodes.runtime import close_spun_node

__all__ = [
    'Collected',
    'Listener',
    'StartNode',
    'node_processes',
    'replay_and_collect',
    'start_predictor',
]

#: Deadline for a node to start and connect (imports torch and scipy on a loaded machine) [s].
STARTUP_S = 120.0
#: After the replay ends, how long to wait for the last outputs and diagnostics [s].
DRAIN_S = 10.0
#: Deadline for a node to exit after SIGINT before it is killed [s].
STOP_S = 15.0
#: Characters of a node's log quoted in an error.
LOG_TAIL_CHARS = 3000
#: Listener queue depth [messages]: a whole second of stalls at 125 Hz.
LISTEN_DEPTH = 1000

#: ``start(module, parameters, remaps)``: start a node process.
StartNode = Callable[[str, dict[str, object], dict[str, str]], NodeProcess]


# -- node processes -------------------------------------------------------------------------------
def _failure(node: NodeProcess, what: str) -> OnlineCheckError:
    return OnlineCheckError(
        f'{node.module} node {what} (exit status {node.process.poll()}); its log ends with:\n'
        f'{node.log()[-LOG_TAIL_CHARS:]}'
    )


def _node_environment(domain_id: int) -> dict[str, str]:
    """The whole environment (the wheels' bootstrap needs LD_LIBRARY_PATH) in our domain."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    env['PYTHONUNBUFFERED'] = '1'
    # The children import this very package, whatever their working directory.
    package_root = str(Path(id_learning.__file__).resolve().parents[1])
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [package_root, env.get('PYTHONPATH')]))
    return env


@contextmanager
def node_processes(log_dir: Path, domain_id: int) -> Iterator[StartNode]:
    """Start nodes with ``start(module, parameters, remaps)``.

    Every node started is stopped on exit, also on an error or Ctrl-C.
    """
    started: list[NodeProcess] = []
    env = _node_environment(domain_id)

    def start(module: str, parameters: dict[str, object], remaps: dict[str, str]) -> NodeProcess:
        node = NodeProcess(module, parameters, log_dir / f'{module}.log', env, remaps)
        started.append(node)
        return node

    try:
        yield start
    finally:
        for node in started:  # all at once: each needs a moment to close
            node.interrupt()
        for node in started:
            node.stop(STOP_S)
        if any(node.was_killed for node in started):
            # A killed node leaves Fast DDS shared-memory files behind.
            fastdds = shutil.which('fastdds') or str(Path(sys.executable).parent / 'fastdds')
            if Path(fastdds).exists():
                subprocess.run(
                    [fastdds, 'shm', 'clean'], capture_output=True, timeout=60, check=False
                )


# -- the in-process listener ----------------------------------------------------------------------
def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


class Listener:
    """An rclpy node in this process, spun by a thread: reference, tau_u and diagnostics."""

    def __init__(self, domain_id: int, namespace: str) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        from id_learning.nodes.qos import DIAGNOSTICS_QOS, reference_qos

        self.condition = threading.Condition()
        # (stamp, names, q, v, a) and (stamp, names, tau), in arrival order.
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
            _stamp_ns(msg.header.stamp),
            tuple(msg.joint_names),
            list(point.positions),
            list(point.velocities),
            list(point.accelerations),
        )
        with self.condition:
            self.references.append(item)
            self.condition.notify_all()

    def _on_tau_u(self, msg: Any) -> None:
        item = (_stamp_ns(msg.header.stamp), tuple(msg.name), list(msg.effort))
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

    def wait_for(
        self,
        predicate: Callable[[], bool],
        timeout: float,
        what: str,
        watched: list[NodeProcess],
    ) -> bool:
        """Wait until predicate() holds; False on timeout; a node that exited raises."""
        deadline = time.monotonic() + timeout
        with self.condition:
            while not predicate():
                for node in watched:
                    if not node.is_running:
                        raise _failure(node, f'exited while waiting for {what}')
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.condition.wait(min(left, 0.1))
        return True

    def close(self) -> None:
        """Stop spinning and shut the node and its context down."""
        close_spun_node(self.node, self.executor, self._thread, self._stop)


# -- the check's launch and wait steps ------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Collected:
    """What the listener received, in arrival order; diagnostics are the last of each node."""

    references: list[tuple[int, tuple[str, ...], list[float], list[float], list[float]]]
    outputs: list[tuple[int, tuple[str, ...], list[float]]]
    predictor: dict[str, str]
    replay: dict[str, str]
    n_inputs: int


def start_predictor(
    start: StartNode,
    setup: CheckSetup,
    namespace: str,
    *,
    seconds: float,
    input_depth: int | None,
) -> NodeProcess:
    """Start the predictor node on the artifact, in ``namespace``, listening to its reference."""
    return start(
        'predictor',
        {
            'artifact': str(setup.artifact.resolve()),
            'robot_config': str(setup.robot_config_path.resolve()),
            'input_topic': 'reference',
            'output_topic': 'tau_u',
            # The model itself, as offline: a sample beyond the training range is counted, not
            # served by the physics prior (test/ros/test_predictor.py checks the fallback).
            'out_of_range': 'warn',
            'diagnostics_period_s': 0.25,
            'latency_window': max(4096, round(seconds * NS_PER_S / setup.period_ns) + 64),
            **({} if input_depth is None else {'input_depth': input_depth}),
        },
        {'__ns': namespace, '/diagnostics': f'{namespace}/diagnostics'},
    )


def replay_and_collect(
    start: StartNode,
    predictor: NodeProcess,
    setup: CheckSetup,
    excerpt: Excerpt,
    *,
    domain: int,
    namespace: str,
    say: Callable[[str], None],
) -> Collected:
    """Wait for the predictor, replay the excerpt in real time, wait for the last tau_u.

    Raises:
        OnlineCheckError: a node did not connect, exited early, failed or took too long.
    """
    listener = Listener(domain, namespace)
    try:
        predictor_name = f'id_learning{namespace}/predictor'
        replay_name = f'id_learning{namespace}/replay'
        say('waiting for the predictor to connect')
        # Matched on the writer side: no tau_u can be lost to discovery.
        if not listener.wait_for(
            lambda: int(listener.status(predictor_name).get('tau_u_subscriptions', 0)) >= 1,
            STARTUP_S,
            'the predictor to connect',
            [predictor],
        ):
            raise _failure(predictor, f'did not connect within {STARTUP_S:g} s')
        say(
            f'replaying {excerpt.excerpt_s:.1f} s of the test part from '
            f'{excerpt.excerpt_start_s:.1f} s in real time'
        )
        replay = _start_replay(start, setup, excerpt, namespace)
        _wait_for_replay(replay, predictor, excerpt.excerpt_s)
        n_inputs = len(listener.references)
        say(f'replay done: {n_inputs} references; waiting for the last outputs')
        _drain(listener, predictor, predictor_name)
        with listener.condition:
            return Collected(
                references=list(listener.references),
                outputs=list(listener.outputs),
                predictor=dict(listener.status(predictor_name)),
                replay=dict(listener.status(replay_name)),
                n_inputs=n_inputs,
            )
    finally:
        listener.close()


def _start_replay(
    start: StartNode, setup: CheckSetup, excerpt: Excerpt, namespace: str
) -> NodeProcess:
    """Start the replay node on the excerpt's window, its joint states remapped into namespace."""
    js_topic = setup.robot.topics.joint_states
    return start(
        'replay',
        {
            'bag': str(setup.bag.resolve()),
            'robot_config': str(setup.robot_config_path.resolve()),
            'topics': [js_topic],
            'reference_source': js_topic,
            'reference_topic': 'reference',
            'reference_inputs': 'controller',
            'reference_smoothing_hz': setup.smoothing_hz,
            'start_offset_s': max(excerpt.start_offset_s, 0.0),
            'duration_s': excerpt.duration_s,
            'publish_clock': False,
            # The predictor's and this listener's reference subscriptions.
            'wait_for_subscribers': 2,
            'wait_timeout_s': STARTUP_S,
            'diagnostics_period_s': 1.0,
        },
        {
            '__ns': namespace,
            '/diagnostics': f'{namespace}/diagnostics',
            js_topic: f'{namespace}/replayed{js_topic}',
        },
    )


def _wait_for_replay(replay: NodeProcess, predictor: NodeProcess, excerpt_s: float) -> None:
    """Wait for the replay to end successfully while the predictor keeps running."""
    deadline = time.monotonic() + STARTUP_S + excerpt_s * 1.5
    while replay.is_running:
        if not predictor.is_running:
            raise _failure(predictor, 'exited during the replay')
        if time.monotonic() > deadline:
            raise _failure(replay, 'did not finish in time')
        with suppress(subprocess.TimeoutExpired):
            replay.process.wait(0.2)
    if replay.process.returncode != 0:
        raise _failure(replay, 'failed')


def _drain(listener: Listener, predictor: NodeProcess, predictor_name: str) -> None:
    """Wait (at most ``DRAIN_S``) until the predictor has answered all it will ever answer."""
    with listener.condition:
        reports = listener.diagnostics_count.get(predictor_name, 0)

    def is_drained() -> bool:
        values = listener.status(predictor_name)
        if len(listener.outputs) < int(values.get('published', 0)):
            return False  # tau_u still on its way
        if int(values.get('received', -1)) >= len(listener.references):
            return True
        # Some references never reached the node. The replay ends once its samples are
        # acknowledged, i.e. in the node's input queue: two reports later it has handled
        # all it will ever get.
        return listener.diagnostics_count.get(predictor_name, 0) >= reports + 2

    listener.wait_for(
        is_drained,
        DRAIN_S,
        'the last tau_u',
        [predictor],
    )
