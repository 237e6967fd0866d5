"""Messages <-> core types: the only place that knows field names of ROS messages.

Stamps are int nanoseconds in the core (``stamp_ns``); arrays are float64 numpy. Joint order is
left as the sender's: the core reorders by name.
"""

from __future__ import annotations

import array
import importlib
import struct
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from id_learning.bag.messages import canonical_cdr
from id_learning.errors import ConfigError
from id_learning.predictor.sample import ReferenceSample

__all__ = [
    'DIAGNOSTIC_LEVELS',
    'SerializedOutput',
    'clock_message',
    'diagnostic_array',
    'joint_state_message',
    'joint_state_to_sample',
    'message_class',
    'ns_to_time',
    'ros_type_name',
    'serialize_exact',
    'time_from_start_ns',
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
        out: type = getattr(importlib.import_module(f'{package}.{kind}'), name)
        return out
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

    A message without points gives empty arrays and says so (``lacks``): the core rejects it as a
    shape error naming that.
    """
    if not msg.points:
        return ReferenceSample(
            time_to_ns(msg.header.stamp),
            tuple(msg.joint_names),
            _EMPTY,
            _EMPTY,
            lacks='the JointTrajectory has no points',
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


def time_from_start_ns(msg: JointTrajectory) -> int:
    """The first point's time_from_start [ns] (0 without points): when it is meant for."""
    if not msg.points:
        return 0
    offset = msg.points[0].time_from_start
    return int(offset.sec) * NS_PER_S + int(offset.nanosec)


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


# -- bytes out ------------------------------------------------------------------------------------
def ros_type_name(msg_class: type) -> str:
    """'pkg/msg/Type' of an rclpy message class."""
    return f'{msg_class.__module__.split(".")[0]}/msg/{msg_class.__name__}'


def serialize_exact(msg: Any) -> bytes:
    """CDR bytes of an rclpy message at their exact size (``bag.messages.canonical_cdr``).

    Every node publishes these bytes rather than the message, so that a recorder's raw
    subscription writes what strict readers (rosbags, the package's reader) accept.
    """
    return canonical_cdr(serialize_message(msg), ros_type_name(type(msg)))


class SerializedOutput:
    """An output message serialized once, of which only the stamp and the values change.

    ``make(stamp_ns, values)`` (a msg_conversions builder) is serialized once with recognisable
    values; their byte offsets in the CDR buffer are found and checked by a round trip. Per
    sample the buffer is copied and patched and the bytes published: ~2 us, against ~13 us to
    build a JointState and have rclpy convert it, joint names included, on every publish.

    Args:
        make: builds the message from a stamp [ns] and n float64 values.
        msg_type: the message class (for the start-up round trip).
        n: values per message.
        has_stamp: the message carries the stamp (a header's, or a Clock's).

    Raises:
        RuntimeError: the values or the stamp cannot be located in the serialized buffer.
    """

    def __init__(
        self,
        make: Callable[[int, np.ndarray], Any],
        msg_type: type,
        n: int,
        *,
        has_stamp: bool = True,
    ) -> None:
        """Serialize the template and locate the fields to patch."""
        stamp = (1_234_567_891, 987_654_321)
        marker = np.pi + np.arange(1, n + 1) / 7.0
        raw = serialize_exact(make(stamp[0] * NS_PER_S + stamp[1], marker))
        if raw[:2] != b'\x00\x01':
            raise RuntimeError(f'expected little-endian CDR, got encapsulation {raw[:4]!r}')
        self._template = raw
        self._n_bytes = 8 * n
        self._values_at = self._find(raw, marker.astype('<f8').tobytes()) if n else 0
        self._stamp_at = self._find(raw, struct.pack('<iI', *stamp)) if has_stamp else None
        # Round trip: the patched bytes must read back as what make() builds.
        values = np.arange(n, dtype=float) - 0.5
        back = deserialize_message(self.serialize(2 * NS_PER_S + 3, values), msg_type)
        if back != make(2 * NS_PER_S + 3, values):
            raise RuntimeError(f'patched {msg_type.__name__} does not read back as built')

    @staticmethod
    def _find(raw: bytes, pattern: bytes) -> int:
        at = raw.find(pattern)
        if at < 0 or raw.find(pattern, at + 1) >= 0:
            raise RuntimeError('cannot locate a field in the serialized template')
        return at

    def serialize(self, stamp_ns: int, values: np.ndarray) -> bytes:
        """The serialized message for a stamp [ns] and n float64 values."""
        buffer = bytearray(self._template)
        if self._stamp_at is not None:
            struct.pack_into('<iI', buffer, self._stamp_at, *divmod(stamp_ns, NS_PER_S))
        at = self._values_at
        buffer[at : at + self._n_bytes] = values.astype('<f8', copy=False).tobytes()
        return bytes(buffer)
