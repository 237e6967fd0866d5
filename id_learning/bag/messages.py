"""CDR encoding of the message types the bag contract uses, without rclpy (through rosbags).

Also the one judgement on the order of a topic's messages that the readers share
(``clock_step``): a rosbag2 reader returns messages in log-time order (the recorder's clock),
but a JointState's header stamp is the sample's time. When the recorder's clock stepped back
while recording, the two orders differ, and header-stamp order is the one that holds.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

from id_learning.header_stamps import NS_PER_S, header_stamp_problem

__all__ = [
    'JOINT_STATE',
    'ClockStep',
    'JointStateMessage',
    'JointStateSeries',
    'canonical_cdr',
    'clock_step',
    'decode_joint_state',
    'encode_joint_state',
    'header_stamp_problem',
    'message_definition',
    'typestore',
]

JOINT_STATE = 'sensor_msgs/msg/JointState'


@cache
def typestore() -> Any:
    """The ROS 2 Jazzy message types known to rosbags."""
    return get_typestore(Stores.ROS2_JAZZY)


@cache
def message_definition(msgtype: str) -> tuple[str, str]:
    """Return (ros2msg definition text, RIHS01 type hash) of a message type."""
    store = typestore()
    text, _ = store.generate_msgdef(msgtype, ros_version=2)
    return text, store.hash_rihs01(msgtype)


def canonical_cdr(data: bytes | memoryview, msgtype: str) -> bytes:
    """The CDR bytes of a message at their exact size, as every reader accepts them.

    rclpy's serializer pads some messages (one ending in an empty array: 8 trailing bytes)
    beyond what strict readers allow ("CDR message size mismatch" in rosbags and in the
    package's reader), and fills alignment gaps with whatever was in memory; a raw subscription
    records those bytes as published. This reads the message without the size check and writes
    it again: same layout, zeroed gaps, no trailing bytes.

    Raises:
        ValueError: the bytes are not a CDR ``msgtype``.
    """
    store = typestore()
    raw = bytes(data)
    if len(raw) < 4 or raw[:2] not in (b'\x00\x00', b'\x00\x01'):
        raise ValueError(f'not CDR-encapsulated {msgtype}: header {raw[:4]!r}')
    msgdef = store.get_msgdef(msgtype)
    read = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
    try:
        message, _ = read(raw[4:], 0, msgdef.cls, store)
    except (struct.error, UnicodeDecodeError, ValueError) as err:
        raise ValueError(f'not a CDR {msgtype}: {err}') from err
    return bytes(store.serialize_cdr(message, msgtype, little_endian=bool(raw[1])))


@dataclass(frozen=True, eq=False)
class JointStateMessage:
    """One decoded sensor_msgs/JointState. Arrays may be empty where the sender left them out.

    ``stamp_problem``: why the header stamp is no time (``header_stamp_problem``), else None;
    ``stamp_ns`` is then sec * 1e9 + nanosec as stored.
    """

    stamp_ns: int
    frame_id: str
    name: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    stamp_problem: str | None = None


def encode_joint_state(
    stamp_ns: int,
    name: tuple[str, ...] | list[str],
    position: np.ndarray,
    velocity: np.ndarray,
    effort: np.ndarray,
    *,
    frame_id: str = '',
) -> bytes:
    """Serialize a JointState to CDR bytes; stamp_ns is the header stamp [ns since epoch]."""
    store = typestore()
    time_type = store.types['builtin_interfaces/msg/Time']
    header_type = store.types['std_msgs/msg/Header']
    msg_type = store.types[JOINT_STATE]
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    msg = msg_type(
        header=header_type(stamp=time_type(sec=sec, nanosec=nanosec), frame_id=frame_id),
        name=list(name),
        position=np.ascontiguousarray(position, dtype=np.float64),
        velocity=np.ascontiguousarray(velocity, dtype=np.float64),
        effort=np.ascontiguousarray(effort, dtype=np.float64),
    )
    return bytes(store.serialize_cdr(msg, JOINT_STATE))


def decode_joint_state(data: bytes | memoryview) -> JointStateMessage:
    """Deserialize CDR bytes of a JointState."""
    msg = typestore().deserialize_cdr(data, JOINT_STATE)
    sec, nanosec = int(msg.header.stamp.sec), int(msg.header.stamp.nanosec)
    return JointStateMessage(
        stamp_ns=sec * NS_PER_S + nanosec,
        frame_id=msg.header.frame_id,
        name=tuple(msg.name),
        position=msg.position,
        velocity=msg.velocity,
        effort=msg.effort,
        stamp_problem=header_stamp_problem(sec, nanosec),
    )


@dataclass(frozen=True, eq=False)
class JointStateSeries:
    """The JointState messages of one topic, stacked.

    Attributes:
        topic: topic name.
        stamps_ns: (N,) header stamps [ns].
        log_ns: (N,) bag log times [ns].
        names: joint names, in the messages' order.
        position: (N, n); velocity and effort (N, n) or None when the messages leave them empty.
    """

    topic: str
    stamps_ns: np.ndarray
    log_ns: np.ndarray
    names: tuple[str, ...]
    position: np.ndarray | None
    velocity: np.ndarray | None
    effort: np.ndarray | None


@dataclass(frozen=True, eq=False)
class ClockStep:
    """A topic whose log times step back where its header stamps advance: read in stamp order.

    Attributes:
        order: (N,) the positions of the messages in log-time order, in header-stamp order.
        sample: the first sample (in header-stamp order) logged after the first step back.
        step_ns: how far the log times step back there, against the header stamps' advance
            [ns] (> 0): the size of the step of the recorder's clock.
        steps: how many times the log times step back in header-stamp order.
        backward: how many times the header stamps step back in log-time order.
    """

    order: np.ndarray
    sample: int
    step_ns: int
    steps: int
    backward: int

    def describe(self, topic: str) -> str:
        """The finding in words, naming the topic, the sample and the size of the step.

        The reader adds what it did about it (read in header-stamp order).
        """
        more = f' ({self.steps} times in all)' if self.steps > 1 else ''
        return (
            f'{topic}: the log times step back by {self.step_ns * 1e-9:.3f} s at sample '
            f'{self.sample}{more} while the header stamps advance (a clock step on the recording '
            f'machine): in log-time order the header stamps would step back {self.backward} '
            'times'
        )


#: A step longer than this many median steps breaks a time series (as ``inspect``'s gaps).
_BREAK_STEPS = 1.5


def _breaks(times: np.ndarray) -> int:
    """How many steps of a time series are no regular step: backward, or a gap."""
    steps = np.diff(times)
    positive = steps[steps > 0]
    gap = _BREAK_STEPS * float(np.median(positive)) if positive.size else np.inf
    return int(np.count_nonzero((steps < 0) | (steps > gap)))


def clock_step(stamps_ns: np.ndarray, log_ns: np.ndarray) -> ClockStep | None:
    """Whether a topic's messages, in log-time order, are in header-stamp order after a clock step.

    Header stamps that step back in log-time order have two explanations: the sender stamped
    samples back (its clock stepped), or the recorder's clock stepped back and its log times
    put later samples before or among earlier ones. The second is taken when header-stamp
    order has strictly increasing stamps (no repeats), its log times step back, and it breaks
    the two time series (header stamps and log times: a step back or a gap) fewer times than
    log-time order does: one clock step on the recorder interleaves many samples (or leaves a
    silence in the log times), one sample stamped back by its sender moves one. Where both
    orders break as often (a single sample out of place), the data cannot tell the causes
    apart and the header stamps are left to be refused.

    Args:
        stamps_ns: (N,) header stamps in log-time order [ns].
        log_ns: (N,) their log times [ns].

    Returns:
        The step and the header-stamp order, or None: the stamps already increase, repeat, or
        do not fit a clock step.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    logs = np.asarray(log_ns, dtype=np.int64)
    backward = int(np.count_nonzero(np.diff(stamps) < 0))
    if not backward:
        return None
    order = np.argsort(stamps, kind='stable')
    back = np.flatnonzero(np.diff(logs[order]) < 0)
    if np.any(np.diff(stamps[order]) <= 0) or not back.size:
        return None
    if _breaks(stamps[order]) + _breaks(logs[order]) >= _breaks(stamps) + _breaks(logs):
        return None
    k = int(back[0]) + 1
    advance = int(stamps[order[k]] - stamps[order[k - 1]])
    logged = int(logs[order[k]] - logs[order[k - 1]])
    return ClockStep(
        order=order, sample=k, step_ns=advance - logged, steps=int(back.size), backward=backward
    )
