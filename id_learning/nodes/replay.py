"""replay: play a bag as the controller would publish it, at the recorded IPO pace.

The selected span of the bag is loaded once. Messages are grouped into cycles by their header stamp
(``timing: stamp``; the bag contract's topics share one stamp per IPO cycle) or by their log time
(``timing: log_time``). Cycle k is published at the absolute deadline

    t_k = t_start + (key_k - key_first) / rate

on the monotonic clock, waiting with a timed wait on each deadline (never sleep(period), so errors
do not accumulate). A late cycle is published at once and the schedule is kept. Each cycle
publishes, in order: /clock (the cycle's stamp, for use_sim_time), the bag's original serialized
bytes of each message (rclpy publishes bytes as they are), then the reference.

The reference (``reference_mode``) is built up front from the ``reference_source`` joint states
with ``predictor.reference_from_states``, as a controller would send it (``reference_inputs``): by
default recorded q and v smoothed far above the motion's band (the robot's ``input_smoothing_hz``,
the inputs models are fitted and scored on; not the labels' 0.3-1.2 Hz low-pass), and a = central
differences of v over the stamps (the replay knows the whole trajectory, like the controller's
interpolator). It is published as a one-point trajectory_msgs/JointTrajectory (q, v, a) or a
sensor_msgs/JointState (q, v), stamped with the sample's stamp.

A header stamp that is no time (``nanosec`` >= 1e9 or a negative ``sec``) refuses the bag, naming
the message, wherever the replay reads stamps (every topic with ``timing: stamp``, the reference
source always). Topics only played (``timing: log_time``) go out as recorded. A reference source of
other joints than the robot config's is refused first; then the stamps pass train's timing checks,
in the bag's order (``replay_span``): one that repeats or goes backwards, or a hole inside the span
in the reference source, refuses the bag, naming it. A reference source sampled off the robot's IPO
period is refused; with ``timing: log_time``, log times that do not advance refuse it.

Jitter: each cycle's lateness (publish time minus its deadline) is recorded; the median, 99th
percentile and maximum [ms] and the cycles later than one IPO period are logged at the end and
published on /diagnostics. With ``loop`` the bag starts again one period after its last cycle
(/clock then jumps back).

Usage: ``ros2 run id_learning replay --ros-args -p bag:=bags/default -p rate:=1.0``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.duration import Duration
from rclpy.publisher import Publisher
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from id_learning.bag import JOINT_STATE, bag_info, decode_joint_state, iter_raw
from id_learning.dataset.consistency import KinematicConsistency, gap_starts
from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.plausibility import check_accelerations, check_motion
from id_learning.errors import BagError, ConfigError, DatasetError
from id_learning.nodes.endpoints import endpoint, refuse_clashing_topics
from id_learning.nodes.msg_conversions import (
    SerializedOutput,
    clock_message,
    diagnostic_array,
    joint_state_message,
    message_class,
    serialize_exact,
    trajectory_message,
)
from id_learning.nodes.params import (
    ReplayConfig,
    declare_parameters,
    read_snapshot,
    resolve_robot_config,
    validate_change,
)
from id_learning.nodes.qos import CLOCK_QOS, DIAGNOSTICS_QOS, reference_qos, sensor_qos
from id_learning.nodes.replay_span import (
    check_timing,
    check_topics_play,
    header_stamp_ns,
    source_stretch,
    stamp_notes,
)
from id_learning.nodes.runtime import NameClash, ShellNode, run_node
from id_learning.predictor.reference import reference_from_states
from id_learning.predictor.timing import RollingStats
from id_learning.robot.config import RobotConfig, load_robot_config

__all__ = ['Cycle', 'Replay', 'ReplayPlan', 'build_plan', 'main']

NODE_NAME = 'replay'
NS_PER_S = 1_000_000_000
#: Lead time between the end of the set-up and the first deadline [ns].
START_LEAD_NS = 20_000_000
#: Joint states read beyond each end of the span for the reference's zero-phase filter [s].
REFERENCE_PAD_S = 10.0
_NO_VALUES = np.empty(0)


@dataclass
class Cycle:
    """What is published at one deadline.

    Attributes:
        offset_ns: time after the first cycle at rate 1 [ns].
        stamp_ns: the cycle's stamp, published on /clock [ns].
        messages: (topic index, serialized bytes) in bag order, then the reference (index -1).
    """

    offset_ns: int
    stamp_ns: int
    messages: list[tuple[int, bytes]] = field(default_factory=list)


@dataclass
class ReplayPlan:
    """The cycles of the replayed span and the topics they publish on."""

    topics: tuple[str, ...]
    msg_types: tuple[str, ...]
    cycles: list[Cycle]
    period_ns: int
    #: What the node logs as warnings before playing (an unpaired tail).
    warnings: tuple[str, ...] = ()

    @property
    def duration_ns(self) -> int:
        """From the first to the last cycle at rate 1 [ns]."""
        return self.cycles[-1].offset_ns if self.cycles else 0

    @property
    def message_count(self) -> int:
        """Messages of the bag's topics (without /clock and the reference)."""
        return sum(1 for cycle in self.cycles for index, _ in cycle.messages if index >= 0)


def _reference_bytes(
    config: ReplayConfig, robot: RobotConfig, states: list[bytes], keep: list[bool]
) -> list[bytes | None]:
    """Serialized reference messages built from the source topic's joint states, in order.

    The reference is computed over all ``states`` (the span plus padding, so that the zero-phase
    filter's edge transients fall outside the span) and serialized where ``keep`` is set.
    """
    decoded = []
    for k, data in enumerate(states):
        try:
            decoded.append(decode_joint_state(data))
        except Exception as err:  # foreign bytes: SerdeError and others
            raise BagError(
                f'{config.bag}: {config.reference_source} message {k} of the replayed span is '
                f'not a valid JointState ({type(err).__name__}: {err})'
            ) from err
    if len(decoded) < 3:
        raise BagError(
            f'{config.bag}: {config.reference_source} has {len(decoded)} messages in the '
            'replayed span; a reference needs at least 3'
        )
    names = decoded[0].name
    if any(msg.name != names for msg in decoded):
        raise BagError(f'{config.bag}: joint names change within {config.reference_source}')
    stamps = np.array([msg.stamp_ns for msg in decoded], dtype=np.int64)
    q = np.vstack([msg.position for msg in decoded])
    v = np.vstack([msg.velocity for msg in decoded])
    limits = None
    if set(names) == set(robot.joints) and len(names) == len(robot.joints):
        limits = robot.limits.take([robot.joints.index(name) for name in names])
    try:
        where = f'{config.bag}: {config.reference_source}'
        check_motion(tuple(names), stamps, q, v, limits=limits, where=where)
    except DatasetError as err:
        raise BagError(f'{err}; nothing is played from an impossible reference') from err
    inputs = None
    if config.reference_inputs != 'recorded':  # the robot's cut-offs, in the bag's joint order
        order = [robot.joints.index(name) for name in names]
        if config.reference_inputs == 'study':
            inputs = InputDefinition.study(robot.lowpass_cutoff_hz[order])
        elif config.reference_smoothing_hz > 0:
            inputs = InputDefinition.controller(np.full(len(names), config.reference_smoothing_hz))
        else:
            inputs = InputDefinition.controller(robot.input_smoothing_hz[order])
    try:
        reference = reference_from_states(
            names, stamps, q, v, period_s=robot.ipo_period_s, inputs=inputs
        )
    except DatasetError as err:
        raise BagError(f'{config.bag}: {config.reference_source}: {err}') from err
    if limits is not None:  # the accelerations the predictor will be sent, bounded as it does
        try:
            check_accelerations(
                tuple(names), reference.stamps_ns, reference.a, limits=limits, where=where
            )
            # Recorded positions and velocities must describe one motion (the predictor's gate).
            KinematicConsistency.for_robot(robot, tuple(names)).check(
                stamps, q, v, where=where, starts=gap_starts(stamps, robot.ipo_period_s, 3.0)
            )
        except DatasetError as err:
            raise BagError(f'{err}; nothing is played from an impossible reference') from err
    out: list[bytes | None] = []
    for k, stamp in enumerate(reference.stamps_ns.tolist()):
        if not keep[k]:
            out.append(None)
            continue
        if config.reference_mode == 'trajectory':
            msg: Any = trajectory_message(
                stamp, names, reference.q[k], reference.v[k], reference.a[k]
            )
        else:
            msg = joint_state_message(
                stamp, names, position=reference.q[k], velocity=reference.v[k]
            )
        out.append(serialize_exact(msg))
    return out


def _check_joint_names(config: ReplayConfig, robot: RobotConfig, data: bytes) -> None:
    """Refuse a reference of other joints than the robot's, before the timing (as train does)."""
    try:  # foreign bytes are refused, with the message's number, in _reference_bytes
        names = decode_joint_state(data).name
    except Exception:
        names = robot.joints
    if config.reference_inputs != 'recorded' and sorted(names) != sorted(robot.joints):
        raise BagError(
            f'{config.bag}: {config.reference_source} joints {list(names)} are not the robot '
            f'{robot.name} joints {list(robot.joints)}; set robot_config to the robot of the '
            'bag, or reference_inputs recorded'
        )


def check_smoothing(config: ReplayConfig, robot: RobotConfig) -> None:
    """Refuse a reference_smoothing_hz the robot config would refuse as input_smoothing_hz.

    It must lie above the label cut-offs (the reference keeps the motion the labels smear:
    models are fitted and scored on such inputs) and below the Nyquist frequency of the IPO.
    """
    hz, nyquist = config.reference_smoothing_hz, 0.5 / robot.ipo_period_s
    if config.reference_mode == 'none' or config.reference_inputs != 'controller' or hz == 0:
        return
    cutoffs = robot.lowpass_cutoff_hz.tolist()
    if not max(cutoffs) < hz < nyquist:
        raise ConfigError(
            f'node replay: reference_smoothing_hz {hz:g} Hz must lie above the label cut-offs '
            f'lowpass_cutoff_hz {cutoffs} of robot config {robot.source or robot.name} (the '
            'reference keeps the motion the labels smear, as input_smoothing_hz does) and below '
            f"the Nyquist frequency {nyquist:g} Hz of the IPO period; 0: the robot config's "
            f'input_smoothing_hz {robot.input_smoothing_hz.tolist()}'
        )


def build_plan(config: ReplayConfig, robot: RobotConfig) -> ReplayPlan:
    """Load the replayed span of a bag into cycles.

    Only the span (with ``REFERENCE_PAD_S`` around it for the reference) is read and kept.

    Raises:
        BagError: the bag is unreadable, lacks a topic, or a message has no header stamp with
            ``timing: stamp``; a topic yields no message in the span, or its type in
            metadata.yaml differs from the storage's; the reference's joints are not the robot's.
        ConfigError: the span is empty, or reference_smoothing_hz is refused (``check_smoothing``).
    """
    check_smoothing(config, robot)
    path = Path(config.bag)
    info = bag_info(path)
    has_reference = config.reference_mode != 'none'
    needed = list(dict.fromkeys(config.topics))
    if has_reference and config.reference_source not in needed:
        needed.append(config.reference_source)
    types = {name: info.topic(name).msgtype for name in needed}
    if has_reference and types[config.reference_source] != JOINT_STATE:
        raise BagError(
            f'{path}: reference_source {config.reference_source} has type '
            f'{types[config.reference_source]}, expected {JOINT_STATE}'
        )
    index = {topic: k for k, topic in enumerate(config.topics)}
    pad = round(REFERENCE_PAD_S * NS_PER_S) if has_reference else 0
    keyed: list[tuple[int, int, bytes]] = []  # (key, topic index, bytes) inside the span
    states: list[tuple[int, bytes, int]] = []  # (key, bytes, stamp): the source, span + padding
    firsts: dict[str, int] = {}  # the message number of each topic's first kept message
    start = stop = None
    log_to_key = 0
    counts: dict[str, int] = {}  # messages of each topic read so far (for messages)
    for topic, log_ns, data in iter_raw(path, needed):
        counts[topic] = counts.get(topic, -1) + 1
        # Stamps and log (receive) times of a recording differ by milliseconds: skip what lies
        # more than a second before the span without decoding it.
        if start is not None and log_ns + log_to_key < start - pad - NS_PER_S:
            continue
        key = log_ns
        is_source = has_reference and topic == config.reference_source
        if config.timing == 'stamp' or is_source:  # the reference carries the source's stamps
            stamp = header_stamp_ns(data, types[topic], f'{path}: {topic} message {counts[topic]}')
            if stamp is None:
                raise BagError(
                    f'{path}: {topic} ({types[topic]}) has no header stamp; use timing:=log_time'
                )
            key = stamp if config.timing == 'stamp' else log_ns
        if start is None:
            log_to_key = key - log_ns
            start = key + round(config.start_offset_s * NS_PER_S)
            if config.duration_s > 0:
                stop = start + round(config.duration_s * NS_PER_S)
        if stop is not None and key > stop + pad + NS_PER_S:
            break  # the bag is in log-time order: nothing later belongs to the span
        if is_source and start - pad <= key and (stop is None or key <= stop + pad):
            firsts.setdefault('', counts[topic])
            assert stamp is not None  # a source's stamp is always read, above
            states.append((key, data, stamp))
        if topic in index and key >= start and (stop is None or key <= stop):
            firsts.setdefault(topic, counts[topic])
            keyed.append((key, index[topic], data))
    if start is None:
        raise ConfigError(f'{path}: no messages on {needed}')

    played = [sum(1 for _, i, _ in keyed if i == k) for k in range(len(config.topics))]
    checked = [*config.topics, *([config.reference_source] if has_reference else [])]
    if keyed:  # an empty span altogether is refused below as nothing to play
        check_topics_play(
            path,
            checked,
            [*played, *([len(states)] if has_reference else [])],
            {topic.name: topic.count for topic in info.topics},
            f'start_offset_s {config.start_offset_s} s, duration_s {config.duration_s} s',
        )

    def inside(key: int) -> bool:
        return key >= start and (stop is None or key <= stop)

    if has_reference and states:  # the joints, then train's timing checks, in the bag's order
        _check_joint_names(config, robot, states[0][1])
        stretch = source_stretch(
            f'{path}: {config.reference_source}',
            [(key, stamp, inside(key)) for key, _, stamp in states],
            period_s=robot.ipo_period_s,
            origin_ns=start - round(config.start_offset_s * NS_PER_S),
            first=firsts[''],
        )
        states = sorted(states[stretch], key=lambda item: item[0])
    check_timing(path, config.topics, config.timing, [item[:2] for item in keyed], firsts)
    by_key: dict[int, Cycle] = {}
    for key, topic_index, data in sorted(keyed, key=lambda item: item[0]):
        by_key.setdefault(key, Cycle(0, key)).messages.append((topic_index, data))
    if has_reference and states:
        keep = [inside(key) for key, _, _ in states]
        references = _reference_bytes(config, robot, [data for _, data, _ in states], keep)
        for (key, _, _), reference in zip(states, references, strict=True):
            if reference is not None:
                by_key.setdefault(key, Cycle(0, key)).messages.append((-1, reference))
    if not by_key:
        raise ConfigError(
            f'{path}: nothing to play after start_offset_s {config.start_offset_s} s '
            f'(duration_s {config.duration_s} s)'
        )
    cycles = [by_key[key] for key in sorted(by_key)]
    origin = cycles[0].stamp_ns
    for cycle in cycles:
        cycle.offset_ns = cycle.stamp_ns - origin
    return ReplayPlan(
        tuple(config.topics),
        tuple(types[t] for t in config.topics),
        cycles,
        round(robot.ipo_period_s * NS_PER_S),
        stamp_notes(
            path,
            config.topics,
            config.timing,
            [([i for i, _ in cycle.messages], cycle.stamp_ns) for cycle in cycles],
            None if has_reference else robot.ipo_period_s,
        ),
    )


class Replay(ShellNode):
    """Publishes a bag's cycles on their deadlines from a playback thread.

    Args:
        **kwargs: passed to rclpy's Node (context, parameter_overrides, ...).
    """

    def __init__(self, **kwargs: Any) -> None:
        """Declare parameters, load the bag, create the publishers and start playing."""
        super().__init__(NODE_NAME, **kwargs)
        declare_parameters(self, ReplayConfig)
        self.config = read_snapshot(self, ReplayConfig)
        config = self.config
        refuse_clashing_topics(self, config)  # before the bag is read
        self.robot = load_robot_config(resolve_robot_config(config.robot_config))
        self.plan = build_plan(config, self.robot)
        self.done: Future = Future()
        qos = sensor_qos(config.qos_depth)
        self._topic_publishers: list[Publisher] = []
        for k, (topic, msg_type) in enumerate(
            zip(self.plan.topics, self.plan.msg_types, strict=True)
        ):
            with endpoint(self, f'topics[{k}] ({msg_type} in the bag)', topic):
                self._topic_publishers.append(
                    self.create_publisher(message_class(msg_type), topic, qos)
                )
        self._reference: Publisher | None = None
        if config.reference_mode != 'none':
            kind = JointTrajectory if config.reference_mode == 'trajectory' else JointState
            with endpoint(self, 'reference_topic', config.reference_topic):
                self._reference = self.create_publisher(
                    kind, config.reference_topic, reference_qos(config.qos_depth)
                )
        self._clock_publisher = (
            self.create_publisher(Clock, '/clock', CLOCK_QOS) if config.publish_clock else None
        )
        self._clock_bytes = SerializedOutput(lambda stamp_ns, _: clock_message(stamp_ns), Clock, 0)
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.lateness_ns = RollingStats(1 << 16)
        self.cycles_published = 0
        self.messages_published = 0
        self.late_cycles = 0
        self.loops = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._is_playing = False
        self._is_closed = False
        # A replay may end before run_node's first name check (1 s): it also looks as it starts
        # playing and as it finishes, when a twin would play alongside it (run_node shares it).
        self.name_clash = NameClash(self, time.monotonic)
        self._diagnostics_timer = self.create_timer(
            config.diagnostics_period_s, self._publish_diagnostics
        )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        for warning in self.plan.warnings:
            self.get_logger().warning(warning)
        self.get_logger().info(
            f'loaded {len(self.plan.cycles)} cycles ({self.plan.message_count} messages, '
            f'{self.plan.duration_ns / NS_PER_S:.2f} s) of {config.bag}; reference '
            f'{config.reference_mode}, rate {config.rate:g}'
        )
        self._thread = threading.Thread(target=self._play, name='replay', daemon=True)
        self._thread.start()

    # -- playback ---------------------------------------------------------------------------------
    def _all_publishers(self) -> list[Publisher]:
        return [*self._topic_publishers, *([self._reference] if self._reference else [])]

    def _wait_for_subscribers(self) -> None:
        """Wait until the published topics (with /clock) have ``wait_for_subscribers`` in all."""
        wanted = self.config.wait_for_subscribers
        if wanted <= 0:
            return
        deadline = time.monotonic() + self.config.wait_timeout_s
        watched = self._all_publishers()
        if self._clock_publisher is not None:
            watched.append(self._clock_publisher)
        while not self._stop.is_set():
            counts = {p.topic_name: p.get_subscription_count() for p in watched}
            if sum(counts.values()) >= wanted:
                return
            if time.monotonic() > deadline:
                self.get_logger().warning(
                    f'playing with fewer than {wanted} subscriptions after '
                    f'{self.config.wait_timeout_s:g} s: {counts}'
                )
                return
            self._stop.wait(0.01)

    def _play(self) -> None:
        try:
            self._wait_for_subscribers()
            self._is_playing = True
            self.name_clash.check_now()
            start_ns = time.monotonic_ns() + START_LEAD_NS
            while not self._stop.is_set():
                start_ns = self._play_once(start_ns)
                if not self.config.loop or self._stop.is_set():
                    break
                self.loops += 1
            if not self._stop.is_set():
                self._finish()
        except Exception as err:  # the edge of the playback thread: report, never die silently
            self.get_logger().error(f'playback failed: {type(err).__name__}: {err}')
            if not self.done.done():
                self.done.set_result(False)

    def _play_once(self, start_ns: int) -> int:
        """Publish every cycle on its deadline; returns the start of the next loop [ns]."""
        rate = self.config.rate
        publishers = self._topic_publishers
        reference = self._reference
        clock = self._clock_publisher
        clock_bytes = self._clock_bytes
        period_ns = self.plan.period_ns
        deadline = start_ns
        for cycle in self.plan.cycles:
            deadline = start_ns + round(cycle.offset_ns / rate)
            remaining = deadline - time.monotonic_ns()
            if remaining > 0 and self._stop.wait(remaining / NS_PER_S):
                return deadline
            lateness = time.monotonic_ns() - deadline
            if clock is not None:
                clock.publish(clock_bytes.serialize(cycle.stamp_ns, _NO_VALUES))
            for topic_index, data in cycle.messages:
                target = reference if topic_index < 0 else publishers[topic_index]
                assert target is not None
                target.publish(data)
            with self._lock:
                self.lateness_ns.add(lateness)
                self.cycles_published += 1
                self.messages_published += len(cycle.messages)
                if lateness > period_ns:
                    self.late_cycles += 1
        return deadline + round(period_ns / rate)

    def _finish(self) -> None:
        # Reliable delivery of the last cycles before the process may exit.
        for publisher in self._all_publishers():
            publisher.wait_for_all_acked(Duration(seconds=2.0))
        self.name_clash.check_now()
        self.get_logger().info(self.report())
        self._publish_diagnostics()
        if self.config.exit_when_done and not self.config.loop and not self.done.done():
            self.done.set_result(True)

    # -- reports ----------------------------------------------------------------------------------
    def jitter_ms(self) -> dict[str, float]:
        """Lateness of the cycles against their deadlines [ms]: median, p99, max."""
        with self._lock:
            summary = self.lateness_ns.summary()
        return {
            'lateness_median_ms': summary.median * 1e-6,
            'lateness_p99_ms': summary.p99 * 1e-6,
            'lateness_max_ms': summary.max * 1e-6,
        }

    def report(self) -> str:
        """One line: cycles, messages and the publish-time jitter."""
        jitter = self.jitter_ms()
        return (
            f'published {self.cycles_published} cycles ({self.messages_published} messages) at '
            f'rate {self.config.rate:g}; lateness against the '
            f'{self.plan.period_ns * 1e-6:g} ms grid: median {jitter["lateness_median_ms"]:.3f} '
            f'ms, p99 {jitter["lateness_p99_ms"]:.3f} ms, max {jitter["lateness_max_ms"]:.3f} '
            f'ms; {self.late_cycles} cycles later than one period'
        )

    def _publish_diagnostics(self) -> None:
        jitter = self.jitter_ms()
        level = 'warn' if self.late_cycles else 'ok'
        state = 'playing' if self._is_playing else 'waiting for subscribers'
        if self._thread is not None and not self._thread.is_alive():
            state = 'finished'
        values: dict[str, object] = {
            'bag': self.config.bag,
            'state': state,
            'cycles_total': len(self.plan.cycles),
            'cycles_published': self.cycles_published,
            'messages_published': self.messages_published,
            'late_cycles': self.late_cycles,
            'loops': self.loops,
            'rate': self.config.rate,
            **jitter,
        }
        self._diagnostics.publish(
            serialize_exact(
                diagnostic_array(
                    time.time_ns(),
                    name=f'id_learning{self.get_fully_qualified_name()}',
                    hardware_id=self.config.bag,
                    level=level,
                    message=f'{state}: {self.cycles_published}/{len(self.plan.cycles)} cycles',
                    values=values,
                )
            )
        )

    def _on_set_parameters(self, parameters: Sequence[Any]) -> SetParametersResult:
        changed, reason = validate_change(self.config, {p.name: p.value for p in parameters})
        if changed is None:
            return SetParametersResult(successful=False, reason=reason)
        if changed.diagnostics_period_s != self.config.diagnostics_period_s:
            self._diagnostics_timer.timer_period_ns = round(changed.diagnostics_period_s * 1e9)
        self.config = changed
        return SetParametersResult(successful=True)

    def close(self) -> None:
        """Stop the playback thread and log the jitter report."""
        if self._is_closed:
            return
        self._is_closed = True
        self._stop.set()
        self._thread.join(timeout=3.0)
        if not self.done.done():
            self.get_logger().info(f'stopped: {self.report()}')


def main(args: Sequence[str] | None = None) -> int:
    """Play a bag; returns the exit status when done (or on SIGINT/SIGTERM)."""
    return run_node(Replay, args, name='replay', config_class=ReplayConfig)


if __name__ == '__main__':
    raise SystemExit(main())
