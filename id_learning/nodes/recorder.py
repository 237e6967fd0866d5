"""recorder: write the bag contract's topics to a rosbag2 MCAP bag, crash-safe.

Subscriptions are raw: the serialized CDR bytes as received are stored unchanged (never
re-serialized; rclpy's serializer pads messages that end in an empty array, which rosbags then
refuses). The log time of a message is its receive time: on the system clock, or on the replay's
/clock when use_sim_time is set. Under use_sim_time with no /clock yet (ROS time reads 0) when
the first message comes, the whole recording is logged on the system clock instead (one time
base per bag; log times of 0 could neither split the bag nor schedule a ``timing: log_time``
replay), with a warning, said again in the final summary and on /diagnostics. The flush and
diagnostics timers run on the steady clock: a /clock that stands still stops neither.

Crash safety: a timer flushes the writer every ``flush_period_s`` (<= 0.5 s), which ends the
MCAP chunk in progress and pushes it to the file. After a SIGKILL the bag lacks its summary and
``metadata.yaml`` but holds every message received up to one flush period before the kill;
``id-learning bag recover PATH`` rebuilds it. On a clean shutdown (SIGINT, SIGTERM) the bag is
finished with ``metadata.yaml`` and the counts are logged.

Counts, per topic and in total: received (callbacks run), written (in the bag file: in a chunk
handed to the OS, see ``bag.writer``; it trails received by up to one flush period), dropped (lost
on the way -- gaps in each publisher's sequence numbers (``sequence_gaps``), which include
messages a full subscription queue overwrote; with the events executor, the middleware's
message-lost events) and lost (received, but never in the file because a write failed). They are
published on /diagnostics every ``diagnostics_period_s``. A topic that has received nothing
``SILENT_AFTER_S`` after another's first message is warned of once; the final summary is a
warning naming each topic that received nothing (the bag lacks it).

A write that fails (disk full, a file size limit) ends the recording: one error names the bag and
the OS's reason, nothing more is written, the final summary gives per topic the messages
received, written and lost, and the process exits with status 1. Every message counted written is
in the file and comes back with ``id-learning bag recover``.

A publisher of another message type on a recorded topic cannot be matched (nothing of it reaches
the bag): the recorder looks at the topics' publishers on every diagnostics period, warns once per
publisher and type found, naming both types and the publisher's node, and lists it on
/diagnostics (level warn). Several publishers of the recorded type on one topic interleave two
streams in the bag (train refuses their stamps going back and forth): that look names them once
per episode (``endpoints.ForeignPublishers.newly_shared``), and /diagnostics lists them (level
warn); topics many nodes share by design (``MERGED_TYPES``: /diagnostics, /rosout, /tf) are not
warned of. Header stamps are recorded as sent, never read: a stamp that is no
time (``nanosec`` >= 1e9) is the replay's and the predictor's to refuse.

Topics are checked before anything is recorded: one recorded twice (also under two names that
resolve to one) is refused, and so is /diagnostics recorded as another type than the
DiagnosticArray the recorder publishes there itself (as that type, its own reports are recorded
with everyone else's).

Usage: ``ros2 run id_learning recorder --ros-args -p output:=runs/excitation_01``.
"""

from __future__ import annotations

import contextlib
import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ROSClock
from rclpy.clock_type import ClockType
from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.task import Future

from id_learning.bag import BagWriter
from id_learning.errors import BagError
from id_learning.nodes.endpoints import (
    ForeignPublishers,
    endpoint,
    refuse_clashing_topics,
    shared_text,
)
from id_learning.nodes.msg_conversions import diagnostic_array, message_class, serialize_exact
from id_learning.nodes.params import (
    RecorderConfig,
    declare_parameters,
    log_change,
    read_snapshot,
    validate_change,
)
from id_learning.nodes.qos import DIAGNOSTICS_QOS, sensor_qos
from id_learning.nodes.runtime import ShellNode, run_node
from id_learning.nodes.sequence_gaps import SequenceGaps
from id_learning.outputs import bag_output

__all__ = ['Recorder', 'TopicCounts', 'main']

NODE_NAME = 'recorder'
#: How messages name the parameters that give the bag and let it be replaced.
OUTPUT_OPTION, OVERWRITE_FLAG = 'output:=PATH', 'overwrite:=true'
#: Types many nodes publish on one topic by design (reports, logs, transforms): several
#: publishers of them are never warned of.
MERGED_TYPES = frozenset(
    {'diagnostic_msgs/msg/DiagnosticArray', 'rcl_interfaces/msg/Log', 'tf2_msgs/msg/TFMessage'}
)
#: What several publishers on a recorded topic do to the bag (``endpoints.shared_text``).
SHARED_TOPIC = (
    'their messages interleave in the bag, two streams whose stamps go back and forth, which '
    'train refuses; leave one publisher on it'
)
#: Messages taken from a subscription's queue per callback, beyond the one the executor hands.
DRAIN_LIMIT = 256
#: Seconds after the first message of any topic before a topic still without one is warned of.
SILENT_AFTER_S = 5.0


@dataclass
class TopicCounts:
    """Messages of one topic: received, written (in the file), dropped on the way, lost."""

    received: int = 0
    written: int = 0
    dropped: int = 0
    #: Received but never in the file: a write failed.
    lost: int = 0


class Recorder(ShellNode):
    """Records raw messages of configured topics into a rosbag2 MCAP bag.

    Args:
        qos: the subscriptions' QoS; None builds it from the parameters (qos_depth,
            reliability) with ``nodes.qos.sensor_qos``.
        **kwargs: passed to rclpy's Node (context, parameter_overrides, ...).
    """

    def __init__(self, qos: QoSProfile | None = None, **kwargs: Any) -> None:
        """Declare parameters, open the bag and subscribe.

        Raises:
            OutputError: ``output`` is refused before anything is recorded (a file, another
                command's result, a parent that cannot be written; ``outputs.check_bag_output``):
                ``main`` logs the line and exits with status 2.
        """
        super().__init__(NODE_NAME, **kwargs)
        declare_parameters(self, RecorderConfig)
        self.config = read_snapshot(self, RecorderConfig)
        config = self.config
        self.done: Future = Future()  # never completes: the recorder runs until shut down
        self.counts = {topic: TopicCounts() for topic in config.topics}
        self.flushes = 0
        #: The failed write that ended the recording, or None.
        self.failure: BagError | None = None
        self._is_closed = False
        #: When the first message of any topic was seen by a flush [monotonic s], or None.
        self._first_message_s: float | None = None
        self._said_silent = False
        qos = qos or sensor_qos(config.qos_depth, config.reliability)
        # rclpy's executors pass message info (the publisher's sequence number) to a
        # two-argument callback: a gap in the sequence is a message lost on the way, including
        # one the middleware dropped from a full subscription queue without telling. The events
        # executor cannot; there only the middleware's message-lost events count.
        self._has_sequence = config.executor != 'events'
        self._gaps = {
            topic: SequenceGaps(functools.partial(self.count_publishers, topic))
            for topic in config.topics
        }
        receive = self._on_message_info if self._has_sequence else self._on_message
        self._uses_system_time = not _ros_time_is_active(self)
        #: Under use_sim_time: the topic whose first message came before any /clock (the whole
        #: recording is then logged on the system clock), and whether /clock came after all.
        self.system_clock_since: str | None = None
        self._clock_came_late = False
        self._by_topic: dict[str, Any] = {}
        refuse_clashing_topics(self, config)
        typed = list(zip(config.topics, config.msg_types, strict=True))
        self._resolved = {topic: self.resolve_topic_name(topic) for topic in config.topics}
        self.foreign = ForeignPublishers(
            self, {self._resolved[topic]: msg_type for topic, msg_type in typed}
        )
        # Its own topic first: a topic that clashes with it is refused by ``endpoint``.
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # Subscribed before the bag is opened (nothing is taken before the node spins): a
        # topic that cannot be subscribed leaves no bag behind.
        for k, (topic, msg_type) in enumerate(typed):
            msg_class = message_class(msg_type)
            events = SubscriptionEventCallbacks(
                message_lost=functools.partial(self._on_lost, topic)
            )
            with endpoint(self, f'topics[{k}]', topic):
                self._by_topic[topic] = self.create_subscription(
                    msg_class,
                    topic,
                    functools.partial(receive, topic),
                    qos,
                    raw=True,
                    event_callbacks=events,
                )
        # The bag's lock is held from here to close(), taken first under the parameter's name
        # (a second recorder on the same output is refused naming 'output'); the writer takes
        # it again and goes on.
        self._output = contextlib.ExitStack()
        self.path = self._output.enter_context(
            bag_output(
                config.bag_path(),
                overwrite=config.overwrite,
                flag=OVERWRITE_FLAG,
                option=OUTPUT_OPTION,
            )
        )
        try:
            self.writer = BagWriter(
                self.path,
                overwrite=config.overwrite,
                flag=OVERWRITE_FLAG,
                chunk_bytes=config.chunk_kib * 1024,
                split_duration_ns=config.split_duration_ns,
                split_bytes=config.split_bytes,
            ).open()
        except BaseException:
            self._output.close()
            raise
        self.path = self.writer.path  # normalised: "a/../b" is b
        for topic, msg_type in typed:  # as subscribed: a relative name in its namespace
            self.writer.add_topic(self._resolved[topic], msg_type)
        steady = Clock(clock_type=ClockType.STEADY_TIME)  # runs whatever /clock does
        self._flush_timer = self.create_timer(config.flush_period_s, self._flush, clock=steady)
        self._diagnostics_timer = self.create_timer(
            config.diagnostics_period_s, self._publish_diagnostics, clock=steady
        )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        resolved = [self._resolved[topic] for topic in config.topics]
        named = '' if resolved == list(config.topics) else f' (resolved: {resolved})'
        self.get_logger().info(
            f'recording {list(config.topics)}{named} to {self.path} (flush every '
            f'{config.flush_period_s:g} s, QoS {config.reliability} depth {config.qos_depth})'
        )

    # -- callbacks --------------------------------------------------------------------------------
    def _on_message(self, topic: str, data: bytes, received_ns: int = 0) -> None:
        log_time_ns = self._log_time(topic, received_ns)
        self.counts[topic].received += 1
        if self.failure is not None:  # the recording has ended: counted as lost
            return
        try:
            self.writer.write(self._resolved[topic], log_time_ns, data)
        except BagError as err:
            self._stop(err)

    def _stop(self, err: BagError) -> None:
        """End the recording after a failed write: one error, then the node finishes."""
        if self.failure is None:
            self.failure = err
            self.get_logger().error(f'recording stopped: {err}')
            self.done.set_result(None)
        self._count_written()

    def _count_written(self) -> None:
        """Take the writer's count of what is in the file; after a failure the rest is lost."""
        for topic, counts in self.counts.items():
            counts.written = self.writer.on_disk.get(self._resolved[topic], 0)
            if self.failure is not None or self._is_closed:
                counts.lost = counts.received - counts.written

    def _on_message_info(self, topic: str, data: bytes, info: dict[str, Any]) -> None:
        self._receive(topic, data, info)
        # Then drain what else is queued on this subscription: rclpy's executor costs several
        # times more per callback than writing a message does. Bounded, so timers still run.
        subscription = self._by_topic[topic]
        for _ in range(DRAIN_LIMIT):
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, True)
            if taken is None:
                return
            self._receive(topic, taken[0], taken[1])

    def _receive(self, topic: str, data: bytes, info: dict[str, Any]) -> None:
        sequence = info.get('publication_sequence_number')
        if sequence is not None:
            # Sequence numbers are per publisher: a gap is counted in one publisher's numbers.
            missing, last = self._gaps[topic].take(sequence)
            if missing > 0:
                self.counts[topic].dropped += missing
                self.get_logger().warning(
                    f'{topic}: {missing} message(s) lost before reception '
                    f'(publisher sequence {last} -> {sequence}): raise qos_depth?',
                    throttle_duration_sec=1.0,
                )
        # The middleware's receive time is the true log time (a drained message waited in the
        # queue); under use_sim_time the node clock (the replay's /clock) is used instead.
        self._on_message(topic, data, info.get('received_timestamp') or 0)

    def _log_time(self, topic: str, received_ns: int) -> int:
        """A message's log time: its receive time on the system clock, or on /clock (sim time).

        Under use_sim_time, a message that comes before any /clock (ROS time reads 0) puts the
        whole recording on the system clock, with one warning: one time base per bag.
        """
        if self._uses_system_time:
            return received_ns or self.get_clock().now().nanoseconds
        if self.system_clock_since is None:
            now = self.get_clock().now().nanoseconds
            if now > 0:
                return now
            self.system_clock_since = topic
            self.get_logger().warning(
                f'use_sim_time is set, but no /clock had come (ROS time reads 0) when {topic} '
                'sent its first message: this recording is logged on the system clock, at the '
                'receive times, instead of at 0 (log times of 0 could neither split the bag nor '
                'schedule a timing: log_time replay); start the /clock publisher first (replay '
                'publish_clock:=true), or set use_sim_time:=false'
            )
        return received_ns or time.time_ns()

    def _on_lost(self, topic: str, info: QoSMessageLostInfo) -> None:
        if not self._has_sequence:  # else the sequence gap counts the same messages
            self.counts[topic].dropped += int(info.total_count_change)
        self.get_logger().warning(
            f'{topic}: the middleware lost {info.total_count_change} message(s) '
            f'({info.total_count} in all): subscription queue full? raise qos_depth',
            throttle_duration_sec=1.0,
        )

    def _flush(self) -> None:
        self._uses_system_time = not _ros_time_is_active(self)
        if (
            self.system_clock_since is not None
            and not self._clock_came_late
            and not self._uses_system_time
            and self.get_clock().now().nanoseconds > 0
        ):
            self._clock_came_late = True
            self.get_logger().warning(
                '/clock started after the recording had begun on the system clock: it stays '
                'on the system clock to the end (one time base per bag)'
            )
        for topic, gaps in self._gaps.items():
            if len(gaps) > 1:
                gaps.forget_idle(self.count_publishers(topic))
        self._warn_silent()
        if self.failure is not None:
            return
        try:
            self.writer.flush()
        except BagError as err:
            self._stop(err)
            return
        self.flushes += 1
        self._count_written()

    def silent_topics(self) -> list[str]:
        """The recorded topics that have received nothing so far."""
        return [topic for topic, counts in self.counts.items() if not counts.received]

    def _warn_silent(self) -> None:
        """Once: a topic still silent ``SILENT_AFTER_S`` after another's first message."""
        silent = self.silent_topics()
        if self._said_silent or len(silent) == len(self.counts):
            return
        now = time.monotonic()
        if self._first_message_s is None:
            self._first_message_s = now
        if silent and now - self._first_message_s >= SILENT_AFTER_S:
            self._said_silent = True
            self.get_logger().warning(
                f'nothing received on {", ".join(silent)} for {SILENT_AFTER_S:g} s while other '
                'topics arrive: the bag lacks it so far (is its publisher running, on that '
                'name, with a matching QoS?)'
            )

    def _on_set_parameters(self, parameters: Sequence[Any]) -> SetParametersResult:
        changed, reason = validate_change(self.config, {p.name: p.value for p in parameters})
        if changed is None:
            return SetParametersResult(successful=False, reason=reason)
        if changed.diagnostics_period_s != self.config.diagnostics_period_s:
            self._diagnostics_timer.timer_period_ns = round(changed.diagnostics_period_s * 1e9)
        log_change(self.get_logger(), self.config, changed)
        self.config = changed
        return SetParametersResult(successful=True)

    # -- reports ----------------------------------------------------------------------------------
    def totals(self) -> TopicCounts:
        """Counts summed over topics."""
        return TopicCounts(
            received=sum(c.received for c in self.counts.values()),
            written=sum(c.written for c in self.counts.values()),
            dropped=sum(c.dropped for c in self.counts.values()),
            lost=sum(c.lost for c in self.counts.values()),
        )

    def check_publisher_types(self) -> None:
        """Warn of publishers that spoil a recorded topic.

        Once per publisher and type of a type its topic is not recorded as; once per episode of
        several publishers of the recorded type on one topic (``ForeignPublishers``).
        """
        for item in self.foreign.look():
            self.get_logger().warning(
                f'{item.topic}: a publisher sends {item.msg_type}, but the topic is recorded as '
                f'{self.foreign.expected[item.topic]} (msg_types): none of its messages reach '
                f'the bag (publisher: node {item.node})'
            )
        for topic, msg_type in self.foreign.expected.items():
            if msg_type not in MERGED_TYPES and self.foreign.newly_shared(topic):
                nodes = self.foreign.shared(topic)
                self.get_logger().warning(shared_text(topic, nodes, SHARED_TOPIC))

    def shared_topics(self) -> list[str]:
        """The recorded topics with several publishers at the last look (merged types aside)."""
        return [
            topic
            for topic in self.counts
            if self.foreign.expected[self._resolved[topic]] not in MERGED_TYPES
            and self.foreign.shared(self._resolved[topic])
        ]

    def wrong_types(self, topic: str) -> list[str]:
        """The other types publishers were found to send on a recorded topic."""
        return self.foreign.types_seen(self._resolved[topic])

    def report_values(self) -> dict[str, object]:
        """The diagnostics key-values: totals, then per topic."""
        total = self.totals()
        values: dict[str, object] = {
            'bag': str(self.path),
            'received': total.received,
            'written': total.written,
            'dropped': total.dropped,
            'lost': total.lost,
            'flushes': self.flushes,
            'log_time': self.log_time_base(),
        }
        if self.failure is not None:
            values['failure'] = str(self.failure)
        for topic, counts in self.counts.items():
            values[f'{topic} received'] = counts.received
            values[f'{topic} written'] = counts.written
            values[f'{topic} dropped'] = counts.dropped
            values[f'{topic} lost'] = counts.lost
            if self.wrong_types(topic):
                values[f'{topic} wrong type'] = ', '.join(self.wrong_types(topic))
        for topic in self.shared_topics():
            values[f'{topic} publishers'] = ', '.join(self.foreign.shared(self._resolved[topic]))
        return values

    def log_time_base(self) -> str:
        """Which clock the log times are on, in words."""
        if self.system_clock_since is not None:
            return (
                f'the system clock (use_sim_time, but no /clock when {self.system_clock_since} '
                'sent its first message)'
            )
        return 'the system clock' if self._uses_system_time else '/clock (use_sim_time)'

    def _publish_diagnostics(self) -> None:
        self.check_publisher_types()
        total = self.totals()
        wrong = [topic for topic in self.counts if self.wrong_types(topic)]
        shared = self.shared_topics()
        fallback = self.system_clock_since is not None
        troubled = total.dropped or wrong or shared or fallback
        level = 'error' if self.failure else 'warn' if troubled else 'ok'
        message = (
            f'{total.written} written, {total.dropped} dropped'
            if total.received
            else 'waiting for messages'
        )
        if self.failure is not None:
            message = f'recording stopped, a write failed; {message}, {total.lost} lost'

        if wrong:
            message += f'; a publisher of another type on {", ".join(wrong)}'
        if shared:
            message += f'; several publishers on {", ".join(shared)}'
        if fallback:
            message += '; logged on the system clock: use_sim_time without /clock'
        self._diagnostics.publish(
            serialize_exact(
                diagnostic_array(
                    self.get_clock().now().nanoseconds,
                    name=f'id_learning{self.get_fully_qualified_name()}',
                    hardware_id=str(self.path),
                    level=level,
                    message=message,
                    values=self.report_values(),
                )
            )
        )

    def close(self) -> None:
        """Finish the bag (summary, ``metadata.yaml``) and log the counts."""
        if self._is_closed:
            return
        self._is_closed = True
        try:
            self.writer.close()
        except BagError as err:
            self._stop(err)
        finally:
            self._output.close()
        self._count_written()
        total = self.totals()
        lines = [
            f'recorded to {Path(self.path).resolve()}: received {total.received}, written '
            f'{total.written}, dropped {total.dropped}, lost {total.lost}'
        ]
        lines += [
            f'  {topic}: received {c.received}, written {c.written}, dropped {c.dropped}, '
            f'lost {c.lost}'
            for topic, c in self.counts.items()
        ]
        if self.system_clock_since is not None:
            lines.append(f'log times: {self.log_time_base()}')
        if self.failure is not None:
            lines.append(
                f'a write failed: the {total.written} message(s) written are in the file, the '
                f'{total.lost} lost are not; id-learning bag recover {self.path} gives back the '
                'written ones'
            )
            self.get_logger().error('\n'.join(lines))
        elif silent := self.silent_topics():
            them = 'it' if len(silent) == 1 else 'them'
            lines.append(
                f'nothing received on {", ".join(silent)}: the bag has no messages of {them} '
                '(was its publisher running, on that name?)'
            )
            self.get_logger().warning('\n'.join(lines))
        else:
            self.get_logger().info('\n'.join(lines))


def _ros_time_is_active(node: Node) -> bool:
    """Whether the node's clock follows /clock (use_sim_time) rather than the system clock."""
    clock = node.get_clock()
    return isinstance(clock, ROSClock) and clock.ros_time_is_active


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder until SIGINT/SIGTERM or a failed write; returns the exit status.

    Returns:
        0; 1 when a write failed (the recording ended early); 2 when it could not start.
    """
    made: list[Recorder] = []

    def make() -> Recorder:
        made.append(Recorder())
        return made[-1]

    status = run_node(
        make,
        args,
        name='recorder',
        config_class=RecorderConfig,
    )
    return 1 if status == 0 and made and made[0].failure is not None else status


if __name__ == '__main__':
    raise SystemExit(main())
