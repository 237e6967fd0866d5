"""Every QoS profile the nodes use, defined once and passed into the node constructors.

- Sensor topics recorded at the IPO rate (125 Hz): RELIABLE so that a matching reliable publisher
  (ros2_control's joint_state_broadcaster publishes with the system default, reliable) retransmits
  rather than loses; KEEP_LAST with a deep queue (a few hundred ms at the IPO rate) so that a
  writer stall (compression, disk) does not overflow the history. A best-effort publisher only
  matches a best-effort subscription: the recorder's ``reliability`` parameter selects it.
- The predictor's reference input: RELIABLE, KEEP_LAST with a small depth: a sample that waited
  for more than a few cycles is of no use as feed-forward, and the guards drop it anyway.
- The torque output matches ros2_control's forward command controller, which subscribes with the
  system default QoS (RELIABLE, KEEP_LAST 10, VOLATILE); a reliable writer drops what a reader
  has not acknowledged once its history is full, so a consumer that stalls needs a deeper one.
- /clock: BEST_EFFORT, KEEP_LAST 1, as rclpy's and rclcpp's time sources subscribe to it.
- /diagnostics: RELIABLE, KEEP_LAST 10, as diagnostic_aggregator subscribes.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    'CLOCK_QOS',
    'DIAGNOSTICS_QOS',
    'RELIABILITIES',
    'reference_qos',
    'sensor_qos',
    'torque_qos',
]

RELIABILITIES = {
    'reliable': ReliabilityPolicy.RELIABLE,
    'best_effort': ReliabilityPolicy.BEST_EFFORT,
}


def sensor_qos(depth: int = 1000, reliability: str = 'reliable') -> QoSProfile:
    """Joint states and motor currents at the IPO rate, for recording and replaying."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=RELIABILITIES[reliability],
        durability=DurabilityPolicy.VOLATILE,
    )


def reference_qos(depth: int = 10) -> QoSProfile:
    """The reference (q, v, a) the predictor consumes, one sample per IPO cycle."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def torque_qos(depth: int = 10) -> QoSProfile:
    """The predictor's tau_u and command outputs: the system default at ``depth`` 10."""
    return reference_qos(depth)  # the same policies: RELIABLE, KEEP_LAST, VOLATILE


CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)

DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
