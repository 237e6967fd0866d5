"""A whole double for an integer parameter at runtime is taken as that integer (the probe's B05:
``resync_after := 3.0`` was refused with rclpy's reason, which names no parameter)."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.nodes.params import PredictorNodeConfig

pytestmark = pytest.mark.ros


def test_a_whole_double_for_an_integer_parameter_is_set_as_that_integer(domain_id):
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from id_learning.nodes.params import declare_parameters

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = Node('predictor', context=context,
                    parameter_overrides=[Parameter('artifact', value='a')])  # fmt: skip
        try:
            declare_parameters(node, PredictorNodeConfig)
            result = node.set_parameters([Parameter('resync_after', value=3.0)])[0]
            assert result.successful, result.reason  # before: 'Wrong parameter type ...'
            value = node.get_parameter('resync_after')
            assert (value.type_, value.value) == (Parameter.Type.INTEGER, 3)
            refused = node.set_parameters([Parameter('resync_after', value=3.5)])[0]
            assert not refused.successful
            assert node.get_parameter('resync_after').value == 3
        finally:
            node.destroy_node()
    finally:
        context.try_shutdown()
