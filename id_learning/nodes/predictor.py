"""predictor: feed-forward tau_u for every reference sample, from a model artifact of any kind.

For each reference sample (``input_type``: a one-point trajectory_msgs/JointTrajectory, or a
sensor_msgs/JointState) the node converts the message (``msg_conversions``), lets the core
``FeedForwardPredictor`` guard it and predict, and publishes tau_u on ``output_topic`` as a
sensor_msgs/JointState (names in the artifact's order, effort = tau_u [N*m, joint side], header
stamp = the input's stamp) and, when ``command_topic`` is set, as a std_msgs/Float64MultiArray for
a ros2_control forward command controller.

Accelerations come from the reference when it carries them; otherwise the core estimates them
causally: the backward difference of the velocity over the stamps, optionally low-passed
(``acceleration_cutoff_hz``; see ``predictor.acceleration``). The LSTM keeps its own window of the
last 20 samples.

Safety (all decided in the core; logged here throttled by hand, each kind of line at most once
per ``log_throttle_s``, which may change at runtime as rclpy's throttle may not, ``log_throttle``):
nothing non-finite is published; outputs are clamped to the robot's torque limits (times
``torque_limit_scale``) and counted;
samples with wrong joints, NaN or Inf, or stamps that do not advance are rejected with an error
and the node keeps running, and so is a header stamp that is no time (``nanosec`` >= 1e9 or a
negative ``sec``: ``invalid_stamp``, refused here before the core); inputs outside the training
range are counted and warned about; so is a stamp more than one IPO period ahead of the stream's
time base (``future_stamp``). A sender whose stamps advance at another rate than the receive
clock (a replay at a rate other than 1; ``predictor.stamp_rate``, over 2 s, beyond 5 %) is served,
and said: a warning when it starts, a line when it ends, ``stamp_rate_ratio`` on /diagnostics
and the level warn while it lasts. When no valid sample has arrived for ``stale_after_cycles`` IPO
cycles the reference is stale: a watchdog says so (throttled), nothing is published on
``output_topic``, and the command on ``command_topic`` ramps to zero, one IPO period's worth of
the slew limit per cycle (a forward command controller holds its last command), and back towards
tau_u at that rate when the reference resumes (``predictor_command``). The history is reset when
the reference resumes. Said once: a trajectory point whose
time_from_start is not 0 (taken as the current cycle's; ``points_ahead`` on /diagnostics), several
publishers on the input (``input_publishers``), torch_threads beyond the CPU cores it may use.

Diagnostics (/diagnostics, every ``diagnostics_period_s``): input rate, receive-to-publish
latency and compute latency (median, p99, max), counts of predictions, clamps per joint, rejects
per reason, out-of-range samples, stale episodes, IPO cycles the reference's stamps skipped
(samples that never arrived: not sent, lost, or overwritten in a full input queue; also across
holes longer than the stale threshold, so that every cycle from the first stamp to the last is
received or skipped) and samples published later than one IPO period after they arrived. The
level is warn while rejects, clamps, out-of-range samples, skipped cycles or late samples occur
(counts grown since the previous report; the totals stay in the values), and while a publisher of
another message type is on the input topic (DDS never delivers its messages: it is named, with the
``input_type`` that would take them); the stale reference reports warn. ``latency_from`` says where
the latency starts: with rclpy's executors at the middleware's receive timestamp
(``middleware_receive``); with the events executor, which cannot pass that timestamp to the
callback, at the callback's start (``callback_start``), which leaves out the wait between arrival
and dispatch.

Real-time measures (the 8 ms IPO cycle, 125 Hz to 1 kHz): the events executor (C++, the
default) dispatches a sample without rebuilding rclpy's wait set; the model runs its float64
numpy path (``inference``); tau_u is published as a message serialized once at start, of which
only the stamp and the torques are rewritten per sample; the hot path runs a few times before
the first sample (first-call costs); everything allocated while starting is frozen out of the
garbage collector (``gc.freeze``), so that a full collection does not walk torch's and rclpy's
objects in the middle of a cycle.

Usage: ``ros2 run id_learning predictor --ros-args -p artifact:=out/demo/run/models/mlp``.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.qos import QoSProfile
from rclpy.task import Future
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from id_learning.errors import ConfigError
from id_learning.nodes.endpoints import (
    ForeignPublishers,
    OtherPublishers,
    endpoint,
    refuse_clashing_topics,
    refuse_contract_topics,
    shared_text,
)
from id_learning.nodes.log_throttle import ThrottledLog
from id_learning.nodes.msg_conversions import (
    SerializedOutput,
    diagnostic_array,
    joint_state_message,
    joint_state_to_sample,
    serialize_exact,
    time_from_start_ns,
    time_to_ns,
    trajectory_message,
    trajectory_to_sample,
)
from id_learning.nodes.param_ros import read_node_config
from id_learning.nodes.params import (
    PredictorNodeConfig,
    declare_parameters,
    guard_config,
    log_change,
    validate_change,
)
from id_learning.nodes.predictor_command import CommandOutput
from id_learning.nodes.predictor_core import adaptation_loop, build_core
from id_learning.nodes.predictor_report import (
    INPUT_TYPES,
    SHARED_INPUT,
    SHARED_OUTPUT,
    TROUBLES,
    NodeCounts,
    ahead_text,
    count_values,
    final_report,
    foreign_text,
    setup_warnings,
    troubles,
)
from id_learning.nodes.qos import DIAGNOSTICS_QOS, reference_qos, torque_qos
from id_learning.nodes.runtime import ShellNode, run_node
from id_learning.predictor import (
    FeedForwardPredictor,
    ReferenceSample,
    Reject,
    RollingStats,
    StepResult,
)
from id_learning.predictor.guards import stamp_problem
from id_learning.predictor.stamp_rate import StampRate
from id_learning.robot.config import RobotConfig

__all__ = ['Predictor', 'adaptation_loop', 'build_core', 'main', 'make_predictor']

NODE_NAME = 'predictor'
JOINT_STATE = 'sensor_msgs/msg/JointState'


class Predictor(ShellNode):
    """Publishes guarded tau_u for every reference sample, from a ready core.

    The node loads nothing: ``make_predictor`` (what ``main`` runs) reads the parameters, builds
    the core and makes the node around it.

    Args:
        core: the guarded model (with its adaptation loop when ``config.adaptation`` is on),
            warmed up.
        robot: the robot config the core was built for (the guards of a runtime change).
        config: the parameters, declared as the node's with these values.
        input_qos: QoS of the reference subscription; None: ``reference_qos(input_depth)``.
        output_qos: QoS of the tau_u and command publishers; None: ``torque_qos(output_depth)``.
        **kwargs: passed to rclpy's Node (context, namespace, ...).
    """

    def __init__(
        self,
        core: FeedForwardPredictor,
        robot: RobotConfig,
        config: PredictorNodeConfig,
        input_qos: QoSProfile | None = None,
        output_qos: QoSProfile | None = None,
        **kwargs: Any,
    ) -> None:
        """Declare the parameters, advertise, warm the messages up, then subscribe."""
        super().__init__(NODE_NAME, **kwargs)
        declare_parameters(self, PredictorNodeConfig, values=config)
        self.config = config
        self.robot = robot
        self.core = core
        self.done: Future = Future()  # never completes: runs until shut down
        self.names = list(self.core.joint_names)
        self.latency_s = RollingStats(config.latency_window)
        self.counts = NodeCounts()
        #: The TROUBLES counts at the last diagnostics report.
        self._troubles = (0,) * len(TROUBLES)
        self._window_start = (time.monotonic(), 0)
        self._stale_logged_ns = 0
        # Not rclpy's throttle_duration_sec: it may not change between calls, log_throttle_s may.
        self._log = ThrottledLog(self.get_logger(), lambda: self.config.log_throttle_s)
        self.stamp_rate = StampRate()  # the stamps' rate against the receive clock
        self._is_closed = False
        refuse_contract_topics(self, config, robot)
        # Its own topic first: a topic parameter that clashes with it is refused by ``endpoint``.
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        output_qos = output_qos or torque_qos(config.output_depth)
        with endpoint(self, 'output_topic', config.output_topic):
            self._tau_u = self.create_publisher(JointState, config.output_topic, output_qos)
        self._command: CommandOutput | None = None
        if config.command_topic:
            with endpoint(self, 'command_topic', config.command_topic):
                self._command = CommandOutput(
                    self, config.command_topic, output_qos, core, config.zero_command_on_stale
                )
        n = len(self.names)
        self._tau_u_bytes = SerializedOutput(
            lambda stamp_ns, tau: joint_state_message(stamp_ns, self.names, effort=tau),
            JointState,
            n,
        )
        kind: type = JointTrajectory if config.input_type == 'trajectory' else JointState
        self._convert: Callable[[Any], ReferenceSample] = (
            trajectory_to_sample if config.input_type == 'trajectory' else joint_state_to_sample
        )
        # rclpy's executors hand the middleware's receive timestamp to a two-argument callback;
        # the events executor (Jazzy) cannot, so latency is then taken from the callback start.
        callback = self._on_reference if config.executor == 'events' else self._on_reference_info
        self.latency_from = (
            'callback_start' if config.executor == 'events' else 'middleware_receive'
        )
        # Half the stale threshold: a stale reference is noticed within 1.5 thresholds. On the
        # steady clock: a /clock that stops (use_sim_time) must not stop them, nor diagnostics.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._watchdog = self.create_timer(
            max(self.core.config.stale_after_ns * 0.5e-9, 0.002), self._check_stale, clock=steady
        )
        self._diagnostics_timer = self.create_timer(
            config.diagnostics_period_s, self._publish_diagnostics, clock=steady
        )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._measured = self._start_adaptation()
        self._warm_up()
        # Subscribed last, once ready to serve: a sender that waits for this subscription starts
        # only then, and nothing it sends queues (and is overwritten, uncounted) while the model
        # warms up. rclpy passes the message info as a second argument to a callback that takes
        # two; its type hints know only the one-argument form.
        with endpoint(self, 'input_topic', config.input_topic):
            self._subscription = self.create_subscription(
                kind,
                config.input_topic,
                cast(Callable[[Any], None], callback),
                input_qos or reference_qos(config.input_depth),
            )
        taken = {kind: msg_type for msg_type, kind in INPUT_TYPES.items()}[config.input_type]
        self._input_topic = self._subscription.topic_name
        expected = {self._input_topic: taken}
        if self._measured is not None:
            expected[self._measured.topic_name] = JOINT_STATE
        self.foreign = ForeignPublishers(self, expected)
        outputs = {'output_topic': self._tau_u.topic_name}
        if self._command is not None:
            outputs['command_topic'] = self._command.publisher.topic_name
        self.other_publishers = OtherPublishers(self, outputs, SHARED_OUTPUT)
        source = self.core.range.source if self.core.range else 'none'
        self.get_logger().info(
            f'{self.core.model.kind} model from {Path(config.artifact).resolve()}: '
            f'{config.input_type} on {self._subscription.topic_name} -> tau_u on '
            f'{self._tau_u.topic_name}'
            + (f' and {self._command.publisher.topic_name}' if self._command else '')
            + f'; input range check: {source}, out of range: {self.core.out_of_range_action}'
            + (
                f' to the {self.core.fallback.source}'
                if self.core.out_of_range_action == 'fallback' and self.core.fallback
                else ''
            )
            + '; '
            + (self.core.inputs.describe() if self.core.inputs else 'inputs not recorded')
        )
        self._say([(True, text) for text in setup_warnings(self.core, self.config)])  # once

    # -- the hot path -----------------------------------------------------------------------------
    def _warm_up(self) -> None:
        """Pay the first-call costs of the message path (make_predictor warmed the core up)."""
        zeros = np.zeros(len(self.names))
        message = (
            trajectory_message(0, self.names, zeros, zeros, zeros)
            if self.config.input_type == 'trajectory'
            else joint_state_message(0, self.names, position=zeros, velocity=zeros)
        )
        for _ in range(25):
            self._convert(message)
            self._tau_u_bytes.serialize(0, zeros)
            if self._command is not None:
                self._command.warm_up(zeros)

    def _on_reference_info(self, msg: Any, info: Any) -> None:
        self._on_reference(msg, info.get('received_timestamp', 0) if isinstance(info, dict) else 0)

    def _on_reference(self, msg: Any, received_wall_ns: int = 0) -> None:
        receive_ns = time.monotonic_ns()
        try:
            stamp = msg.header.stamp
            problem = stamp_problem(stamp.sec, stamp.nanosec)
            if problem is not None:  # folded into ns it would be another time: refused here
                self._refuse_stamp(problem)
                return
            sample = self._convert(msg)
            if self._convert is trajectory_to_sample:
                self._check_ahead(msg)
            result = self.core.step(sample, receive_ns)
            # O(1); a refused lead would pass for a quick delivery, so it is left out.
            if result.reject is not Reject.FUTURE_STAMP and self.stamp_rate.add(
                sample.stamp_ns, receive_ns
            ):
                self._say([self.stamp_rate.line()])  # when it starts and when it ends
            if result.reject is not None:
                self._log_reject(result)
            if result.resynced:
                self.get_logger().warning(
                    f"the reference's time base changed ({result.detail}): resynchronised at "
                    f'stamp {result.stamp_ns} ns ({self.core.counters.resyncs} so far)'
                )
            if result.tau is None:
                return
            tau = result.tau
            self._tau_u.publish(self._tau_u_bytes.serialize(result.stamp_ns, tau))
            if self._command is not None:
                self._command.send(tau)
            if received_wall_ns:
                latency_s = (time.time_ns() - received_wall_ns) * 1e-9
            else:  # no middleware timestamp: from the callback's start
                latency_s = (time.monotonic_ns() - receive_ns) * 1e-9
            self.latency_s.add(latency_s)
            if latency_s > self.core.config.period_s:
                self.counts.late_samples += 1
            if (
                result.resumed_after_stale
                or result.is_out_of_range
                or result.is_clamped
                or result.is_slew_limited
                or result.physics_share > 0
            ):
                self._log_result(result)
            self.core.prepare_next()  # off the path from sample to torque
        except Exception as err:  # the edge of the callback: report and keep running
            self.counts.callback_errors += 1
            self._log.failure('reference_callback', 'reference callback', err)  # never raises

    def _start_adaptation(self) -> Any:
        """With the core's adaptation loop: continue from the stored file; the currents' topic."""
        if self.core.adaptation is None:
            return None
        self._say([self.core.adaptation.load(Path(self.config.artifact), self.names).line()])
        with endpoint(self, 'measured_topic', self.config.measured_topic):
            return self.create_subscription(
                JointState, self.config.measured_topic, self._on_measured, reference_qos(64)
            )

    def _on_measured(self, msg: JointState) -> None:
        """The drive's currents of a served cycle: the adaptation learns from them."""
        loop = self.core.adaptation
        if loop is None:
            return
        try:
            topic = self._measured.topic_name
            if self.core.is_stale:
                loop.freeze('stale', f'{topic}: the reference is stale')
            else:
                stamp = time_to_ns(msg.header.stamp)
                loop.measured_message(stamp, list(msg.name), list(msg.effort), self.names, topic)
            self._say(loop.take_reasons())  # each kind of reason once
        except Exception as err:  # the edge of the callback: report and keep running
            self.counts.callback_errors += 1
            self._log.failure('measured_callback', 'measured-current callback', err)

    def _say(self, lines: Sequence[tuple[bool, str] | None]) -> None:
        """Log each (is a warning, line) at the warning level, or else at info."""
        for is_warning, line in filter(None, lines):
            if is_warning:
                self.get_logger().warning(line)
            else:
                self.get_logger().info(line)

    def _refuse_stamp(self, problem: str) -> None:
        """Refuse a sample whose header stamp is no time (counted as rejected invalid_stamp)."""
        self.counts.invalid_stamps += 1
        self._log.error(
            'invalid_stamp',
            f'sample refused: no model torque (invalid_stamp): header stamp {problem} '
            f'({self.counts.invalid_stamps} so far)',
        )

    def _check_ahead(self, msg: JointTrajectory) -> None:
        """A point with a time_from_start: counted, and said once (taken as the current one)."""
        ahead_ns = time_from_start_ns(msg)
        if ahead_ns:
            self.counts.points_ahead += 1
            if self.counts.points_ahead == 1:
                self.get_logger().warning(ahead_text(self._input_topic, ahead_ns))

    def _log_reject(self, result: StepResult) -> None:
        held = ', hold output published' if result.is_held else ''
        text = (
            f'sample at {result.stamp_ns} ns: no model torque ({result.reject.value}{held}): '
            f'{result.detail}'
        )
        key = f'reject_{result.reject.value}'  # each reason throttled on its own
        if result.reject in (Reject.OUT_OF_RANGE, Reject.REARMING):
            self._log.warning(key, text)
        else:
            self._log.error(key, text)

    def _log_result(self, result: StepResult) -> None:
        if result.resumed_after_stale:  # resuming is normal: not worth a line at the INFO level
            self.get_logger().debug('reference resumed: publishing again (history reset)')
        if result.is_out_of_range or result.physics_share > 0:
            self._log.warning('out_of_range', f'input outside the training range: {result.detail}')
        if result.is_clamped:
            self._log.warning(
                'clamped',
                f'tau_u clamped to the torque limits ({self.core.counters.clamped_samples} '
                'samples so far)',
            )
        if result.is_slew_limited:
            self._log.warning(
                'slew_limited',
                f'tau_u slew-limited ({self.core.counters.slew_limited_samples} samples so far)',
            )

    def _check_stale(self) -> None:
        now = time.monotonic_ns()
        became_stale = self.core.check_stale(now)
        if not self.core.is_stale:
            return
        if became_stale and self._command is not None:
            self._command.went_stale()  # the command ramps to zero
        # Once when stale, then slowly: a predictor left running must not fill the log.
        period_ns = self.config.stale_log_period_s * 1e9
        if not became_stale and (period_ns <= 0 or now - self._stale_logged_ns < period_ns):
            return
        self._stale_logged_ns = now
        silence_ms = (self.core.silence_ns(now) or 0) * 1e-6
        if became_stale:
            self.get_logger().warning(
                f'reference stale: no valid sample for {silence_ms:.0f} ms (> '
                f'{self.core.config.stale_after_cycles} cycles of '
                f'{self.core.config.period_s * 1e3:g} ms): not publishing tau_u until valid '
                'input returns'
            )
        else:
            self.get_logger().info(f'reference still stale ({silence_ms * 1e-3:.0f} s)')

    # -- parameters and reports -------------------------------------------------------------------
    def _on_set_parameters(self, parameters: Sequence[Any]) -> SetParametersResult:
        changed, reason = validate_change(self.config, {p.name: p.value for p in parameters})
        if changed is None:
            return SetParametersResult(successful=False, reason=reason)
        try:
            self.core.update_config(guard_config(changed, self.robot))
        except ConfigError as err:
            return SetParametersResult(successful=False, reason=str(err))
        if changed.diagnostics_period_s != self.config.diagnostics_period_s:
            self._diagnostics_timer.timer_period_ns = round(changed.diagnostics_period_s * 1e9)
        log_change(self.get_logger(), self.config, changed)
        self.config = changed
        return SetParametersResult(successful=True)

    def report_values(self) -> dict[str, object]:
        """The diagnostics key-values (counts since start; latencies over the last window)."""
        counters = self.core.counters
        received = counters.received + self.counts.invalid_stamps
        now = time.monotonic()
        start, received_then = self._window_start
        self._window_start = (now, received)
        latency, rate = self.latency_s.summary(), self.stamp_rate.ratio
        compute = self.core.compute_s.summary()
        values: dict[str, object] = {
            'model': self.core.model.kind,
            'artifact': self.config.artifact,
            'adaptation': self.config.adaptation,
            'input_rate_hz': (received - received_then) / max(now - start, 1e-9),
            'stamp_rate_ratio': float('nan') if rate is None else rate,  # nan: before a window
            **count_values(self.core, self.counts),
            # Matched on the writer side: a consumer listed here receives every tau_u.
            'tau_u_subscriptions': self._tau_u.get_subscription_count(),
            'latency_from': self.latency_from,
            'latency_median_ms': latency.median * 1e3,
            'latency_p99_ms': latency.p99 * 1e3,
            'latency_max_ms': latency.max * 1e3,
            'latency_samples': latency.count,
            'compute_median_ms': compute.median * 1e3,
            'compute_p99_ms': compute.p99 * 1e3,
            'compute_max_ms': compute.max * 1e3,
        }
        values['input_publishers'] = len(self.foreign.matching.get(self._input_topic, []))
        values['other_output_publishers'] = sum(map(len, self.other_publishers.others.values()))
        if self.foreign.present:
            values['wrong_type_publishers'] = '; '.join(
                f'{item.node} {item.msg_type} on {item.topic}' for item in self.foreign.present
            )
        if self.core.adaptation is not None:
            values.update(self.core.adaptation.report(self.names))
        for label, per_joint in (('clamped', counters.clamped_per_joint),
                                 ('slew_limited', counters.slew_limited_per_joint)):  # fmt: skip
            values.update(
                {f'{label}_{name}': int(n) for name, n in zip(self.names, per_joint, strict=True)}
            )
        return values

    def _check_publishers(self) -> str:
        """Name publishers of another type, several on the input, other nodes on an output.

        Each publisher of another type once; the others once per episode.

        Returns:
            What is there now, in words ('' if nothing).
        """
        topic, foreign = self._input_topic, self.foreign
        for item in foreign.look():
            self.get_logger().warning(foreign_text(item, foreign, topic, self.config.input_type))
        is_new, shared = foreign.newly_shared(topic), foreign.shared(topic)
        texts = [
            foreign_text(item, foreign, topic, self.config.input_type) for item in foreign.present
        ]
        if shared:
            texts.append(shared_text(topic, shared, SHARED_INPUT))
            if is_new:
                self.get_logger().warning(texts[-1])
        self._say(self.other_publishers.look())  # another node on tau_u or the command
        texts.append(self.other_publishers.text())
        return '; '.join(filter(None, texts))

    def _publish_diagnostics(self) -> None:
        foreign = self._check_publishers()  # first: the values show this look
        values = self.report_values()
        counters = self.core.counters
        now_troubles = troubles(self.core, self.counts)
        if self.core.is_stale:
            silence_s = (self.core.silence_ns(time.monotonic_ns()) or 0) * 1e-9
            level, message = 'warn', f'reference stale for {silence_s:.1f} s: not publishing'
        elif counters.received + self.counts.invalid_stamps == 0:
            level, message = 'ok', 'waiting for the reference'
        elif any(now > before for now, before in zip(now_troubles, self._troubles, strict=True)):
            # Warn while troubles occur (counts grew since the last report); totals stay in values.
            grew = [f'{now - before} {name}' for name, now, before in zip(
                TROUBLES, now_troubles, self._troubles, strict=True) if now > before]  # fmt: skip
            level = 'warn'
            message = f'since the last report: {", ".join(grew)}'
        else:
            level, message = 'ok', f'{counters.published} published'
        if self.stamp_rate.is_off:
            level, message = 'warn', f'{message}; {self.stamp_rate.line()[1]}'
        if foreign:
            level, message = 'warn', f'{message}; {foreign}'
        self._diagnostics.publish(
            serialize_exact(
                diagnostic_array(
                    time.time_ns(),
                    name=f'id_learning{self.get_fully_qualified_name()}',
                    hardware_id=self.core.model.kind,
                    level=level,
                    message=message,
                    values=values,
                )
            )
        )
        self._troubles = now_troubles

    def close(self) -> None:
        """Log the final counts and latencies."""
        if self._is_closed:
            return
        self._is_closed = True
        if self.core.adaptation is not None:  # saved only if it learnt, atomically
            self._say([self.core.adaptation.finish(Path(self.config.artifact), self.names)])
        self.get_logger().info(final_report(self.core, self.counts, self.latency_s.summary()))


def make_predictor(
    input_qos: QoSProfile | None = None, output_qos: QoSProfile | None = None, **kwargs: Any
) -> Predictor:
    """Read the parameters, build the core, freeze the garbage collector, make the node.

    Args:
        input_qos, output_qos: as ``Predictor``'s.
        **kwargs: passed to rclpy's Node (context, parameter_overrides, namespace, ...).

    Raises:
        ConfigError, CheckpointError, RobotModelError: bad parameters (topics that clash are
            refused before the artifact is loaded), or as ``build_core``.
    """
    config = read_node_config(NODE_NAME, PredictorNodeConfig, refuse_clashing_topics, **kwargs)
    core, robot = build_core(config)
    # torch, the model and rclpy leave ~10^5 tracked objects; a full collection walks them all
    # (~0.1 s here) when the per-sample allocations trigger one. Frozen, they are never walked.
    gc.collect()
    gc.freeze()
    node = Predictor(core, robot, config, input_qos, output_qos, **kwargs)
    gc.freeze()  # the node's objects too: no collection first, so no pause once it subscribed
    return node


def main(args: Sequence[str] | None = None) -> int:
    """Run the predictor until SIGINT/SIGTERM; returns the exit status."""
    return run_node(
        make_predictor,
        args,
        name='predictor',
        config_class=PredictorNodeConfig,
    )


if __name__ == '__main__':
    raise SystemExit(main())
