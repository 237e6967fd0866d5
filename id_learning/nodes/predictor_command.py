"""The predictor node's command topic: tau_u for a forward command controller.

The commands are the core's ``predictor.command.CommandStream``: each published tau_u, moved by
at most one IPO period's worth of the slew limit per message; when the reference goes stale, a
ramp to zero on a timer of one IPO period (steady clock: a /clock that stops does not stop it),
which the reference resuming ends. The timer runs only while a ramp is under way.
"""

from __future__ import annotations

import numpy as np
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64MultiArray

from id_learning.nodes.msg_conversions import SerializedOutput, torque_command
from id_learning.predictor.command import CommandStream
from id_learning.predictor.feedforward import FeedForwardPredictor

__all__ = ['CommandOutput']


class CommandOutput:
    """Publishes the command stream of ``core`` on ``topic``.

    Args:
        node: the node that publishes (and runs the ramp's timer).
        topic: the command topic.
        qos: its QoS (match the controller).
        core: the predictor whose tau_u is sent.
        ramp_on_stale: ramp to zero when the reference goes stale (``zero_command_on_stale``).
    """

    def __init__(
        self,
        node: Node,
        topic: str,
        qos: QoSProfile,
        core: FeedForwardPredictor,
        ramp_on_stale: bool,
    ) -> None:
        """Advertise, serialize the message once, and make the (stopped) ramp timer."""
        self.publisher: Publisher = node.create_publisher(Float64MultiArray, topic, qos)
        self.stream = CommandStream(core, ramp_on_stale)
        self._bytes = SerializedOutput(
            lambda _, tau: torque_command(tau), Float64MultiArray, len(core.joint_names),
            has_stamp=False,
        )  # fmt: skip
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = node.create_timer(
            core.config.period_s, self._tick, clock=steady, autostart=False
        )

    def warm_up(self, zeros: np.ndarray) -> None:
        """Pay the first-call cost of the message path."""
        self._bytes.serialize(0, zeros)

    def send(self, tau: np.ndarray) -> None:
        """The command for a published tau_u."""
        self.publisher.publish(self._bytes.serialize(0, self.stream.follow(tau)))

    def went_stale(self) -> None:
        """The reference has just gone stale: the ramp's first command now, then one a period."""
        if self.stream.went_stale():
            self._tick()
            if self.stream.is_ramping:
                self._timer.reset()

    def _tick(self) -> None:
        command = self.stream.ramp()
        if command is not None:
            self.publisher.publish(self._bytes.serialize(0, command))
        if not self.stream.is_ramping:
            self._timer.cancel()
