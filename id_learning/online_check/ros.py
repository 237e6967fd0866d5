"""The online check's node steps: start the predictor, replay the excerpt, collect what came back.

The predictor and replay nodes run as separate processes (``nodes.process``) in a private
namespace; this process listens to the reference, tau_u and /diagnostics through a
``nodes.listener.Listener`` (its own rclpy context, imported only when the replay starts).
``start_predictor`` and ``replay_and_collect`` are the check's launch and wait steps; what they
return is compared offline afterwards (``online_check.scoring``).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from typing import TYPE_CHECKING

from id_learning.nodes.params import MAX_QUEUE_DEPTH
from id_learning.nodes.process import NodeProcess, StartNode
from id_learning.online_check.plan import CheckSetup, Excerpt
from id_learning.online_check.result import NS_PER_S, OnlineCheckError

if TYPE_CHECKING:
    from id_learning.nodes.listener import Listener

__all__ = ['Collected', 'replay_and_collect', 'start_predictor']

#: Deadline for a node to start and connect (imports torch and scipy on a loaded machine) [s].
STARTUP_S = 120.0
#: After the replay ends, how long to wait for the last outputs and diagnostics [s].
DRAIN_S = 10.0
#: Characters of a node's log quoted in an error.
LOG_TAIL_CHARS = 3000


def _failure(node: NodeProcess, what: str) -> OnlineCheckError:
    return OnlineCheckError(
        f'{node.module} node {what} (exit status {node.process.poll()}); its log ends with:\n'
        f'{node.log()[-LOG_TAIL_CHARS:]}'
    )


def _wait_for(
    listener: Listener,
    predicate: Callable[[], bool],
    timeout: float,
    what: str,
    watched: list[NodeProcess],
) -> bool:
    """Wait until predicate() holds; False on timeout; a node of ``watched`` that exited raises."""
    if listener.wait(predicate, timeout, lambda: not all(n.is_running for n in watched)):
        return True
    for node in watched:
        if not node.is_running:
            raise _failure(node, f'exited while waiting for {what}')
    return False


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
    max_age_s: float | None = None,
) -> NodeProcess:
    """Start the predictor node on the artifact, in ``namespace``, listening to its reference."""
    samples = round(seconds * NS_PER_S / setup.period_ns) + 64  # the excerpt's and a margin
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
            'latency_window': max(4096, samples),
            # The check's own listener, stalled with the machine, must not lose a tau_u.
            'output_depth': min(samples, MAX_QUEUE_DEPTH),
            **({} if input_depth is None else {'input_depth': input_depth}),
            **({} if max_age_s is None else {'max_age_s': max_age_s}),
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
    from id_learning.nodes.listener import Listener

    listener = Listener(domain, namespace)
    try:
        predictor_name = f'id_learning{namespace}/predictor'
        replay_name = f'id_learning{namespace}/replay'
        say('waiting for the predictor to connect')
        # Matched on the writer side: no tau_u can be lost to discovery.
        if not _wait_for(
            listener,
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

    _wait_for(
        listener,
        is_drained,
        DRAIN_S,
        'the last tau_u',
        [predictor],
    )
