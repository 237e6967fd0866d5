"""CDR encoding of the message types the bag contract uses, without rclpy (through rosbags)."""

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
    'JointStateMessage',
    'JointStateSeries',
    'canonical_cdr',
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
