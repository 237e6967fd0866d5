"""The core's topic name check (config_io.topic_name_problem) agrees with rclpy's validators."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.config_io import topic_name_problem

pytestmark = pytest.mark.ros

#: Pieces of topic names: the characters ROS allows, substitutions, and a few it refuses.
PIECES = ['a', 'b', '1', '_', '/', '~', '{', '}', '{node}', '{ns}', '{namespace}', '{x}', ' ', '-']


def rclpy_problem(name: str) -> str | None:
    """What rclpy says of ``name`` when a node ``node`` in namespace ``/ns`` uses it."""
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name
    from rclpy.validate_topic_name import validate_topic_name

    try:
        validate_topic_name(name)
        validate_full_topic_name(expand_topic_name(name, 'node', '/ns'))
    except Exception as error:  # rclpy raises its own exceptions and ValueError
        return f'{type(error).__name__}: {error}'
    return None


@settings(max_examples=3000, deadline=None)
@given(st.lists(st.sampled_from(PIECES), max_size=9).map(''.join))
def test_the_core_check_accepts_exactly_what_rclpy_accepts(name: str):
    assert (topic_name_problem(name) is None) == (rclpy_problem(name) is None), (
        name,
        topic_name_problem(name),
        rclpy_problem(name),
    )


@pytest.mark.parametrize('length', [245, 246, 247, 248])
def test_the_length_limit_is_rclpys(length: int):
    name = '/' + 'a' * (length - 1)
    assert (topic_name_problem(name) is None) == (rclpy_problem(name) is None)
