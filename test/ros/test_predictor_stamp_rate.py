"""The predictor says when the reference's stamps run at another rate than real time (probe).

A reference published every 4 ms with stamps 8 ms apart was served without a word. The node
feeds the core's ``StampRate`` each sample and reports it: a warning when it starts and a line
when it ends, ``stamp_rate_ratio`` and a WARN level on /diagnostics while it lasts.
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.test_predictor_core import Linear, served

from id_learning.nodes.params import PredictorNodeConfig, guard_config
from id_learning.predictor import FeedForwardPredictor
from id_learning.predictor.stamp_rate import StampRate

pytestmark = pytest.mark.ros

WINDOW_S = 0.5


def test_a_sender_at_twice_real_time_is_served_and_said(mabi, domain_id):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    from id_learning.nodes.msg_conversions import trajectory_message

    config = PredictorNodeConfig(artifact='in-memory')
    core = FeedForwardPredictor(Linear(mabi), mabi.limits.torque, guard_config(config, mabi))
    core.warm_up()
    with served(core, mabi, config, domain_id) as (node, sender, spin_until):
        node.stamp_rate = StampRate(window_s=WINDOW_S)  # a shorter window than the 2 s default
        reports: list[DiagnosticStatus] = []
        sender.create_subscription(
            DiagnosticArray, '/diagnostics', lambda m: reports.extend(m.status), 10
        )
        q, zeros = np.linspace(0.1, 0.6, 6), np.zeros(6)
        stamp_ns, last_ns = time.time_ns(), time.monotonic_ns()

        def send(seconds: float, send_ms: float, stamp_ms: float) -> None:
            """Hand the node a sample every send_ms, stamps stamp_ms apart (as its callback).

            The time since the last call is a hole: the stamps leap it.
            """
            nonlocal stamp_ns, last_ns
            next_ns = time.monotonic_ns()
            stamp_ns += next_ns - last_ns
            for _ in range(round(seconds * 1e3 / send_ms)):
                while time.monotonic_ns() < next_ns:
                    pass  # paced on the clock the node receives with
                next_ns += round(send_ms * 1e6)
                stamp_ns += round(stamp_ms * 1e6)
                node._on_reference(trajectory_message(stamp_ns, mabi.joints, q, zeros, zeros))
            last_ns = time.monotonic_ns()

        send(2 * WINDOW_S, 4.0, 8.0)  # rate 2: every 4 ms, stamps 8 ms apart
        assert node.stamp_rate.is_off
        assert core.counters.rejected == 0  # served all the same
        assert node.counts.callback_errors == 0
        values = node.report_values()
        assert values['stamp_rate_ratio'] == pytest.approx(2.0, rel=0.05)
        spin_until(lambda: node.count_subscribers('/diagnostics') >= 1, 'the diagnostics reader')
        node._publish_diagnostics()
        spin_until(lambda: reports, 'a diagnostics report')
        (report,) = reports
        assert report.level == DiagnosticStatus.WARN
        assert re.search(
            r'advance (1\.9\d|2\.0\d) times as fast as the receive clock', report.message
        )
        (ratio,) = [kv.value for kv in report.values if kv.key == 'stamp_rate_ratio']
        assert float(ratio) == pytest.approx(2.0, rel=0.05)
        send(3 * WINDOW_S, 8.0, 8.0)  # on time again
        assert not node.stamp_rate.is_off
        assert core.counters.rejected == 0
        assert node.report_values()['stamp_rate_ratio'] == pytest.approx(1.0, abs=0.025)
        assert node.counts.callback_errors == 0
