"""Messages <-> core types: the only place that knows field names of ROS messages.

Stamps are int nanoseconds in the core (``stamp_ns``); arrays are float64 numpy. Joint order is
left as the sender's: the core reorders by name.
"""

from __future__ import annotations

import array
import importlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from id_learning.errors import ConfigError
from id_learning.predictor.sample import ReferenceSample

__all__ = [
    'DIAGNOSTIC_LEVELS',
    'clock_message',
    'diagnostic_array',
    'joint_state_message',
    'joint_state_to_sample',
    'message_class',
    'ns_to_time',
    'time_to_ns',
    'torque_command',
    'trajectory_message',
    'trajectory_to_sample',
]

NS_PER_S = 1_000_000_000
DIAGNOSTIC_LEVELS = {
    'ok': DiagnosticStatus.OK,
    'warn': DiagnosticStatus.WARN,
    'error': DiagnosticStatus.ERROR,
    'stale': DiagnosticStatus.STALE,
}
_EMPTY = np.empty(0)


def time_to_ns(stamp: Time) -> int:
    """builtin_interfaces/Time -> int nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_time(stamp_ns: int) -> Time:
    """Int nanoseconds -> builtin_interfaces/Time."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def _floats(values: Any) -> np.ndarray:
    # rclpy gives float64[] fields as array.array('d'): a zero-copy view is enough here.
    if isinstance(values, array.array):
        return np.frombuffer(values, dtype=np.float64) if len(values) else _EMPTY
    return np.asarray(values, dtype=np.float64)


def _doubles(values: np.ndarray | Sequence[float]) -> array.array[float]:
    return array.array('d', np.asarray(values, dtype=np.float64).tobytes())


def message_class(msg_type: str) -> type:
    """The Python class of 'pkg/msg/Type'.

    Raises:
        ConfigError: the package or type is not installed.
    """
    try:
        package, kind, name = msg_type.split('/')
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ValueError, ImportError, AttributeError) as err:
        raise ConfigError(f'unknown message type {msg_type!r}: {err}') from err


# -- reference in ---------------------------------------------------------------------------------
def joint_state_to_sample(msg: JointState) -> ReferenceSample:
    """A JointState reference (position, velocity); accelerations are left to the estimator."""
    return ReferenceSample(
        stamp_ns=time_to_ns(msg.header.stamp),
        names=tuple(msg.name),
        q=_floats(msg.position),
        v=_floats(msg.velocity),
        a=None,
    )


def trajectory_to_sample(msg: JointTrajectory) -> ReferenceSample:
    """The first point of a JointTrajectory; empty accelerations mean 'estimate them'.

    A message without points gives empty arrays, which the core rejects as a shape error.
    """
    if not msg.points:
        return ReferenceSample(
            time_to_ns(msg.header.stamp), tuple(msg.joint_names), _EMPTY, _EMPTY
        )
    point = msg.points[0]
    a = _floats(point.accelerations)
    return ReferenceSample(
        stamp_ns=time_to_ns(msg.header.stamp),
        names=tuple(msg.joint_names),
        q=_floats(point.positions),
        v=_floats(point.velocities),
        a=a if len(a) else None,
    )


# -- messages out ---------------------------------------------------------------------------------
def joint_state_message(
    stamp_ns: int,
    names: Sequence[str],
    *,
    position: np.ndarray | None = None,
    velocity: np.ndarray | None = None,
    effort: np.ndarray | None = None,
) -> JointState:
    """A JointState; fields left out stay empty."""
    msg = JointState()
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.name = list(names)
    if position is not None:
        msg.position = _doubles(position)
    if velocity is not None:
        msg.velocity = _doubles(velocity)
    if effort is not None:
        msg.effort = _doubles(effort)
    return msg


def trajectory_message(
    stamp_ns: int, names: Sequence[str], q: np.ndarray, v: np.ndarray, a: np.ndarray
) -> JointTrajectory:
    """A one-point JointTrajectory carrying the reference of one cycle (time_from_start 0)."""
    msg = JointTrajectory()
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.joint_names = list(names)
    point = JointTrajectoryPoint()
    point.positions = _doubles(q)
    point.velocities = _doubles(v)
    point.accelerations = _doubles(a)
    msg.points = [point]
    return msg


def torque_command(tau: np.ndarray) -> Float64MultiArray:
    """tau_u [N*m] as a ros2_control forward command (one value per joint, artifact order)."""
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label='joints', size=len(tau), stride=len(tau))]
    msg.data = _doubles(tau)
    return msg


def clock_message(stamp_ns: int) -> Clock:
    """A /clock message."""
    return Clock(clock=ns_to_time(stamp_ns))


def diagnostic_array(
    stamp_ns: int,
    *,
    name: str,
    hardware_id: str,
    level: str,
    message: str,
    values: Mapping[str, object],
) -> DiagnosticArray:
    """One DiagnosticStatus in a DiagnosticArray; values are written with str()."""
    status = DiagnosticStatus(
        level=DIAGNOSTIC_LEVELS[level],
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[
            KeyValue(key=key, value=f'{value:.6g}' if isinstance(value, float) else str(value))
            for key, value in values.items()
        ],
    )
    msg = DiagnosticArray()
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.status = [status]
    return msg
