"""rosbag2 MCAP bags: the contract's messages, a writer that keeps serialized bytes, a reader."""

from __future__ import annotations

from id_learning.bag.messages import (
    JOINT_STATE,
    JointStateMessage,
    decode_joint_state,
    encode_joint_state,
    header_stamp_problem,
)
from id_learning.bag.reader import (
    BagInfo,
    JointStateSeries,
    TopicInfo,
    bag_custom_data,
    bag_info,
    iter_messages,
    iter_raw,
    iter_typed,
    read_joint_states,
)
from id_learning.bag.writer import BagWriter

__all__ = [
    'JOINT_STATE',
    'BagInfo',
    'BagWriter',
    'JointStateMessage',
    'JointStateSeries',
    'TopicInfo',
    'bag_custom_data',
    'bag_info',
    'decode_joint_state',
    'encode_joint_state',
    'header_stamp_problem',
    'iter_messages',
    'iter_raw',
    'iter_typed',
    'read_joint_states',
]
