"""Where a node's topics meet the ROS graph: names checked, endpoints made, foreign types named.

- ``refuse_clashing_topics``: the node's topic parameters checked once more with the names it
  resolves (namespace, remaps): 'reference' and '/reference' are one topic in the root namespace.
- ``refuse_contract_topics``: the predictor publishes nothing on the robot's bag contract topics
  (joint_states, motor_currents): the recorder records them, the replay publishes them.
- ``endpoint``: a publisher or subscription that rcl refuses ends the start with one line naming
  the parameter and the topic, not a traceback.
- ``ForeignPublishers``: a publisher of another message type on a topic the node takes in is
  never matched (DDS delivers nothing of it, silently); it is looked for, and named once. The
  same look counts the publishers of the right type: several on a topic whose samples must
  follow one another (the predictor's reference) interleave two motions, which the node then
  names once per episode (``newly_shared``, ``shared_text``).
- ``OtherPublishers``: another node publishing on a topic the node publishes on (a second
  predictor on tau_u, a second replay on /reference): a consumer there takes both streams. Said
  once per episode, naming the other node, on /diagnostics while it lasts, and when it is gone.
"""

from __future__ import annotations

import contextlib
import re
import threading
import time
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from id_learning.errors import ConfigError
from id_learning.nodes.params import (
    PredictorNodeConfig,
    RecorderConfig,
    ReplayConfig,
    refuse_shared_topics,
)

if TYPE_CHECKING:
    from rclpy.node import Node

    from id_learning.robot.config import RobotConfig

__all__ = [
    'EVERY_NODES_TOPICS',
    'Foreign',
    'ForeignPublishers',
    'OtherPublishers',
    'endpoint',
    'refuse_clashing_topics',
    'refuse_contract_topics',
    'shared_text',
]

#: Part of the name the graph gives a publisher before discovery has brought its node's.
UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'
#: How long several publishers wait for such a name before they are said without it [s].
NAME_WAIT_S = 3.0
#: rcl's source locations at the end of its error text.
_WHERE = re.compile(r',\s*at\s+\S+:\d+')
#: The topics every node publishes itself (rclpy's own), with their types: the graph may not
#: list a node's own publishers yet when its next endpoint is refused.
EVERY_NODES_TOPICS = {
    '/parameter_events': 'rcl_interfaces/msg/ParameterEvent',
    '/rosout': 'rcl_interfaces/msg/Log',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',  # each node of this package's
}


def refuse_clashing_topics(
    node: Node, config: RecorderConfig | ReplayConfig | PredictorNodeConfig
) -> None:
    """Refuse topic parameters that resolve to one topic, or to one the node keeps for itself.

    Raises:
        ConfigError: names the node, both parameters and the resolved topic.
    """
    refuse_shared_topics(config, node.resolve_topic_name, f'node {node.get_name()}: ')


def refuse_contract_topics(node: Node, config: PredictorNodeConfig, robot: RobotConfig) -> None:
    """Refuse an output or command topic that resolves to one of the robot's contract topics.

    tau_u there would be recorded into the bag as the robot's joint states or motor currents
    (and replayed, and learnt from as labels). The input topic may be one of them.

    Raises:
        ConfigError: names the node, the parameter, the topic and the robot's topic key.
    """
    contract = {
        robot.topics.joint_states: 'joint_states',
        robot.topics.motor_currents: 'motor_currents',
    }
    for parameter, topic in (
        ('output_topic', config.output_topic),
        ('command_topic', config.command_topic),
    ):
        if not topic:
            continue
        resolved = node.resolve_topic_name(topic)
        key = contract.get(resolved)
        if key is not None:
            raise ConfigError(
                f'node {node.get_name()}: {parameter} {topic!r} resolves to {resolved}, the '
                f"robot's {key} topic (robot config topics.{key}, recorded into bags): the "
                'predictor publishes nothing there'
            )


@contextlib.contextmanager
def endpoint(node: Node, parameter: str, topic: str) -> Iterator[None]:
    """Turn rcl's refusal to create a publisher or subscription into one clear line.

    Raises:
        ConfigError: names the node, the parameter, the topic and rcl's reason.
    """
    try:
        yield
    except RuntimeError as err:  # rclpy's RCLError, e.g. a type that clashes on one topic
        reason = _WHERE.sub('', str(err).splitlines()[0] if str(err) else type(err).__name__)
        # rcl may overwrite its first reason ('invalid allocator'): name what the node has there.
        resolved = node.resolve_topic_name(topic)
        mine = {
            f'a {kind} of {info.topic_type}'
            for kind, infos in (
                ('publisher', node.get_publishers_info_by_topic(resolved)),
                ('subscription', node.get_subscriptions_info_by_topic(resolved)),
            )
            for info in infos
            if info.node_name == node.get_name() and info.node_namespace == node.get_namespace()
        }
        if resolved in EVERY_NODES_TOPICS:
            mine.add(f'a publisher of {EVERY_NODES_TOPICS[resolved]}')
        held = (
            f' (the node itself already has {", ".join(sorted(mine))} on {resolved}: choose '
            'another topic)'
            if mine
            else ''
        )
        raise ConfigError(
            f'node {node.get_name()}: {parameter} {topic!r}: ROS 2 refused the topic: '
            f'{reason}{held}'
        ) from None


@dataclass(frozen=True)
class Foreign:
    """A publisher of another type than the node takes on one of its topics."""

    topic: str
    node: str
    msg_type: str


class ForeignPublishers:
    """Publishers of another message type on the topics a node takes in.

    Args:
        node: the node whose graph is looked at.
        expected: the type the node takes on each topic ('pkg/msg/Type'), by resolved name.
    """

    def __init__(self, node: Node, expected: Mapping[str, str]) -> None:
        self._node = node
        self.expected = dict(expected)
        #: Every one found since start (each is named once).
        self.seen: set[Foreign] = set()
        #: Those present at the last look.
        self.present: list[Foreign] = []
        #: Per topic, the nodes of its publishers of the expected type at the last look (a node
        #: once per publisher, sorted).
        self.matching: dict[str, list[str]] = {}
        #: Per topic shared now: since when (time.monotonic() [s]), or None once said.
        self._shared: dict[str, float | None] = {}
        #: Foreign publishers whose node discovery has not named yet: since when [s].
        self._unnamed: dict[Foreign, float] = {}
        #: The foreign types ever found, by topic (named or not).
        self._types: set[tuple[str, str]] = set()

    def look(self) -> list[Foreign]:
        """Look at the graph; returns the publishers found for the first time.

        One whose node discovery has not named yet waits ``NAME_WAIT_S`` for its name, so that
        a publisher is said once, by its node's name.
        """
        present = []
        matching: dict[str, list[str]] = {}
        for topic, expected in self.expected.items():
            matching[topic] = []
            for info in self._node.get_publishers_info_by_topic(topic):
                node = f'{info.node_namespace.rstrip("/")}/{info.node_name}'
                if info.topic_type != expected:
                    present.append(Foreign(topic, node, info.topic_type))
                else:
                    matching[topic].append(node)
        self.matching = {topic: sorted(nodes) for topic, nodes in matching.items()}
        self.present = sorted(
            set(present), key=lambda item: (item.topic, item.node, item.msg_type)
        )
        self._types.update((item.topic, item.msg_type) for item in self.present)
        now = time.monotonic()
        self._unnamed = {
            item: self._unnamed.get(item, now)
            for item in self.present
            if UNKNOWN_NODE in item.node and item not in self.seen
        }
        new = [
            item
            for item in self.present
            if item not in self.seen
            and (UNKNOWN_NODE not in item.node or now - self._unnamed[item] >= NAME_WAIT_S)
        ]
        self.seen.update(new)
        return new

    def types_seen(self, topic: str) -> list[str]:
        """The foreign types ever found on a topic, sorted."""
        return sorted({msg_type for name, msg_type in self._types if name == topic})

    def shared(self, topic: str) -> list[str]:
        """The nodes of several publishers of the expected type on ``topic``, else [].

        As at the last look; a node once per publisher.
        """
        nodes = self.matching.get(topic, [])
        return nodes if len(nodes) > 1 else []

    def newly_shared(self, topic: str) -> bool:
        """Whether ``topic`` has several publishers now, not yet said: call once per look.

        What is said once: again only after it had one publisher or none in between. A
        publisher whose node name discovery has not brought yet waits ``NAME_WAIT_S`` for it.
        """
        nodes = self.shared(topic)
        if not nodes:
            self._shared.pop(topic, None)
            return False
        since = self._shared.setdefault(topic, time.monotonic())
        if since is None:
            return False
        unnamed = any(UNKNOWN_NODE in node for node in nodes)
        if unnamed and time.monotonic() - since < NAME_WAIT_S:
            return False
        self._shared[topic] = None
        return True


def shared_text(topic: str, nodes: list[str], consequence: str) -> str:
    """'2 publishers on /reference (node /a, node /b twice): ...' for several publishers."""
    counts = Counter(nodes)
    named = ', '.join(
        ('a node not discovered yet' if UNKNOWN_NODE in node else f'node {node}')
        + ('' if n == 1 else ' twice' if n == 2 else f' {n} times')
        for node, n in sorted(counts.items())
    )
    return f'{len(nodes)} publishers on {topic} ({named}): {consequence}'


def _node_of(info: Any) -> str:
    """'/namespace/name' of an endpoint's node (a TopicEndpointInfo)."""
    return f'{info.node_namespace.rstrip("/")}/{info.node_name}'


class OtherPublishers:
    """Publishers of other nodes on the topics a node publishes on (its outputs).

    A consumer of such a topic takes every publisher's messages: two predictors on one tau_u
    give it two torques per cycle, from two models; two replays on one reference interleave two
    motions. The node's own publisher is left out (once per topic: a second node of its very
    name counts, ``NameClash`` names that). ``look`` may be called from several threads.

    Args:
        node: the node whose graph is looked at.
        topics: each output's resolved topic, by the parameter that names it.
        consequence: what the other publishers do there, ending the warning.
    """

    def __init__(self, node: Node, topics: Mapping[str, str], consequence: str) -> None:
        self._node = node
        self.topics = dict(topics)
        self._consequence = consequence
        self._lock = threading.Lock()
        #: Per topic, the other publishers' nodes at the last look (sorted, one per publisher).
        self.others: dict[str, list[str]] = {}
        #: Per topic with others: since when (time.monotonic() [s]), or None once said.
        self._since: dict[str, float | None] = {}

    def look(self) -> list[tuple[bool, str]]:
        """Look at the graph; the lines to log: (is a warning, text), each episode said once.

        A warning when other publishers are found (after up to ``NAME_WAIT_S`` for discovery
        to name their nodes), a line when they are gone again.
        """
        me = f'{self._node.get_namespace().rstrip("/")}/{self._node.get_name()}'
        lines: list[tuple[bool, str]] = []
        with self._lock:
            now = time.monotonic()
            for parameter, topic in self.topics.items():
                infos = self._node.get_publishers_info_by_topic(topic)
                mine = {info.topic_type for info in infos if _node_of(info) == me}
                nodes = sorted(
                    _node_of(info)
                    + ('' if not mine or info.topic_type in mine else f' ({info.topic_type})')
                    for info in infos
                )
                if me in nodes:
                    nodes.remove(me)
                self.others[topic] = nodes
                if not nodes:
                    if self._since.pop(topic, 0.0) is None:
                        lines.append((False, f'{topic} ({parameter}): no other publisher now'))
                    continue
                since = self._since.setdefault(topic, now)
                unnamed = any(UNKNOWN_NODE in node for node in nodes)
                if since is None or (unnamed and now - since < NAME_WAIT_S):
                    continue
                self._since[topic] = None
                lines.append((True, self._text(parameter, topic, nodes)))
        return lines

    def _text(self, parameter: str, topic: str, nodes: list[str]) -> str:
        if all(node.endswith(')') for node in nodes):  # all of another type than this node's
            return (
                f"another publisher on {topic}, the topic of this node's {parameter}, of "
                f'another type: {", ".join(f"node {node}" for node in nodes)}; a topic of two '
                'types: a consumer takes only '
                "its own type's messages, but tools see both: give one of them another topic"
            )
        counts = Counter(nodes)
        named = ', '.join(
            ('a node not discovered yet' if UNKNOWN_NODE in node else f'node {node}')
            + ('' if n == 1 else f' ({n} publishers)')
            for node, n in sorted(counts.items())
        )
        return (
            f"another publisher on {topic}, the topic of this node's {parameter}: {named}; "
            f'{self._consequence}'
        )

    def text(self) -> str:
        """What is there now, in words, for /diagnostics ('' if nothing)."""
        with self._lock:
            return '; '.join(
                self._text(parameter, topic, self.others[topic])
                for parameter, topic in self.topics.items()
                if self.others.get(topic)
            )
