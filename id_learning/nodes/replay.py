"""replay: play a bag as the controller would publish it, at the recorded IPO pace.

The selected span of the bag is loaded once (``replay_plan``). Messages are grouped into cycles by
their header stamp (``timing: stamp``; the bag contract's topics share one stamp per IPO cycle) or
by their log time (``timing: log_time``). Cycle k is published at the absolute deadline

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
source always). Topics only played (``timing: log_time``) go out as recorded. With ``timing:
stamp``, a topic whose log times step back while its header stamps advance (a clock step on the
recorder, ``bag.messages.clock_step``) is played in header-stamp order, as train reads it, with one
warning naming the step. A reference source of other joints than the robot config's is refused
first; then the stamps pass train's timing checks, in play order (``replay_span``): one that
repeats or goes backwards (a sender's stamps out of order), or a hole inside the span in the
reference source, refuses the bag, naming it. A reference source sampled off the robot's IPO
period is refused; with ``timing: log_time``, log times that do not advance refuse it.

Jitter: each cycle's lateness (publish time minus its deadline) is recorded; the median, 99th
percentile and maximum [ms] and the cycles later than one played period (the IPO period / rate)
are logged at the end and published on /diagnostics. With ``loop`` the bag starts again one
period after its last cycle (/clock then jumps back). A play longer than an hour of wall time
(its duration / rate) is said as it starts.

From before the bag is read until it closes, the replay holds the bag shared
(``outputs.read_lock``, ``<bag>.lock`` beside it): a writer that would replace it meanwhile (a
recorder with ``overwrite``) is refused, naming the replay. Where that file cannot be made (a
folder nobody may write into, where nobody can replace the bag either), it plays without it.

Usage: ``ros2 run id_learning replay --ros-args -p bag:=bags/default -p rate:=1.0``.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Sequence
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

from id_learning.nodes.endpoints import (
    UNKNOWN_NODE,
    OtherPublishers,
    endpoint,
    refuse_clashing_topics,
)
from id_learning.nodes.msg_conversions import (
    SerializedOutput,
    clock_message,
    diagnostic_array,
    message_class,
    serialize_exact,
)
from id_learning.nodes.params import (
    ReplayConfig,
    declare_parameters,
    log_change,
    read_snapshot,
    resolve_robot_config,
    validate_change,
)
from id_learning.nodes.qos import CLOCK_QOS, DIAGNOSTICS_QOS, reference_qos, sensor_qos
from id_learning.nodes.replay_plan import Cycle, ReplayPlan, build_plan
from id_learning.nodes.runtime import NameClash, ShellNode, run_node
from id_learning.outputs import read_lock
from id_learning.predictor.timing import RollingStats
from id_learning.robot.config import load_robot_config

__all__ = ['Cycle', 'Replay', 'ReplayPlan', 'build_plan', 'long_play_warning', 'main']

NODE_NAME = 'replay'
NS_PER_S = 1_000_000_000
#: Lead time between the end of the set-up and the first deadline [ns].
START_LEAD_NS = 20_000_000
#: A play longer than this in wall time is said as the replay starts [s].
LONG_PLAY_S = 3600.0
#: The longest single wait on a deadline [s] (threading's waits refuse more than ~292 years).
MAX_WAIT_S = 3600.0
#: What another node's publisher on a topic the replay plays does (``OtherPublishers``).
SHARED_TOPIC = (
    'a subscriber there takes both streams, interleaved (a second replay, the robot or a '
    'simulator): stop the other, or play into another namespace (-r __ns:=/NAME)'
)
_NO_VALUES = np.empty(0)


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
        # The bag is held shared from before it is read until close(): a writer that would
        # replace it meanwhile (a recorder with overwrite) is refused, naming this replay.
        self._bag_lock = contextlib.ExitStack()
        try:
            self._bag_lock.enter_context(read_lock(Path(config.bag)))
            self.plan = build_plan(config, self.robot)
        except BaseException:
            self._bag_lock.close()
            raise
        self.done: Future = Future()
        # The node's own topics first: a topic parameter that clashes with one of them is then
        # refused by ``endpoint``, naming the parameter, never a traceback (the probe's B74).
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self._clock_publisher = (
            self.create_publisher(Clock, '/clock', CLOCK_QOS) if config.publish_clock else None
        )
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
        played = {
            f'topics[{k}]': publisher.topic_name
            for k, publisher in enumerate(self._topic_publishers)
        }
        if self._reference is not None:
            played['reference_topic'] = self._reference.topic_name
        self.other_publishers = OtherPublishers(self, played, SHARED_TOPIC)
        self._clock_bytes = SerializedOutput(lambda stamp_ns, _: clock_message(stamp_ns), Clock, 0)
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
        said = long_play_warning(self.plan.duration_ns, config.rate, loop=config.loop)
        if said:
            self.get_logger().warning(said)
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
            counts = {p.topic_name: self._others_subscribed(p.topic_name) for p in watched}
            if sum(counts.values()) >= wanted:
                return
            if time.monotonic() > deadline:
                self.get_logger().warning(
                    f'playing with fewer than {wanted} subscriptions after '
                    f'{self.config.wait_timeout_s:g} s: {counts}'
                )
                return
            self._stop.wait(0.01)

    def _others_subscribed(self, topic: str) -> int:
        """Subscriptions to ``topic`` of other nodes (with use_sim_time this one reads /clock).

        One whose node discovery has not named yet is not counted until it is: it may be this
        node's own (the wait goes on, a real subscriber is named within moments).
        """
        own = (self.get_name(), self.get_namespace())
        return sum(
            (info.node_name, info.node_namespace) != own and info.node_name != UNKNOWN_NODE
            for info in self.get_subscriptions_info_by_topic(topic)
        )

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
            while remaining > 0:
                if self._stop.wait(min(remaining / NS_PER_S, MAX_WAIT_S)):
                    return deadline
                remaining = deadline - time.monotonic_ns()
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
                if lateness * rate > period_ns:  # later than one played period
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
            f'{self.plan.period_ns * 1e-6 / self.config.rate:g} ms grid: median '
            f'{jitter["lateness_median_ms"]:.3f} '
            f'ms, p99 {jitter["lateness_p99_ms"]:.3f} ms, max {jitter["lateness_max_ms"]:.3f} '
            f'ms; {self.late_cycles} cycles later than one period'
        )

    def _publish_diagnostics(self) -> None:
        for is_warning, line in self.other_publishers.look():  # each episode said once
            if is_warning:
                self.get_logger().warning(line)
            else:
                self.get_logger().info(line)
        others = self.other_publishers.text()
        jitter = self.jitter_ms()
        level = 'warn' if self.late_cycles or others else 'ok'
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
                    message=f'{state}: {self.cycles_published}/{len(self.plan.cycles)} cycles'
                    + (f'; {others}' if others else ''),
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
        log_change(self.get_logger(), self.config, changed)
        self.config = changed
        return SetParametersResult(successful=True)

    def close(self) -> None:
        """Stop the playback thread and log the jitter report."""
        if self._is_closed:
            return
        self._is_closed = True
        self._stop.set()
        self._thread.join(timeout=3.0)
        self._bag_lock.close()
        if not self.done.done():
            self.get_logger().info(f'stopped: {self.report()}')


def long_play_warning(duration_ns: int, rate: float, *, loop: bool) -> str | None:
    """What to say of a play longer than ``LONG_PLAY_S`` in wall time, or None.

    A slow rate stretches the bag: 4 s at rate 0.001 take over an hour, with nothing published
    between the cycles but /diagnostics.
    """
    wall_s = duration_ns / NS_PER_S / rate
    if wall_s <= LONG_PLAY_S:
        return None
    return (
        f'{duration_ns / NS_PER_S:.3g} s of the bag at rate {rate:g} take {wall_s / 3600:.2g} h '
        f'of wall time{" each loop" if loop else ""} (duration / rate); raise rate to play '
        'faster'
    )


def main(args: Sequence[str] | None = None) -> int:
    """Play a bag; returns the exit status when done (or on SIGINT/SIGTERM)."""
    return run_node(Replay, args, name='replay', config_class=ReplayConfig)


if __name__ == '__main__':
    raise SystemExit(main())
