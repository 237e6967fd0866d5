"""The launch file, read statically: launch_ros is not on PyPI, so it cannot run here.

What ``ros2 launch`` would trip over is checked against the package itself: every node is one of
the package's console scripts, every node reads the one parameter file and has its section there,
every parameter the launch sets is one the node declares, every launch argument used is declared.
"""

from __future__ import annotations

import ast
import dataclasses
import re

import pytest
import yaml
from support import REPO

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.nodes.params import PredictorNodeConfig, RecorderConfig, ReplayConfig

pytestmark = pytest.mark.ros

LAUNCH = REPO / 'launch/id_learning.launch.py'
NODE_CONFIGS = {
    'recorder': RecorderConfig,
    'replay': ReplayConfig,
    'predictor': PredictorNodeConfig,
}
#: Parameters every rclpy node has without declaring them.
BUILT_IN = {'use_sim_time'}


def _calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == name
    ]


def _assigned_dicts(tree: ast.AST) -> dict[str, ast.Dict]:
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    out[target.id] = node.value
    return out


def launch_nodes() -> dict[str, dict]:
    """Per node executable: its name, the parameter sources, the keys it overrides."""
    tree = ast.parse(LAUNCH.read_text())
    dicts = _assigned_dicts(tree)
    nodes = {}
    for call in _calls(tree, 'Node'):
        keywords = {k.arg: k.value for k in call.keywords}
        parameters = keywords['parameters']
        assert isinstance(parameters, ast.List)
        overrides, sources = set(), []
        for element in parameters.elts:
            is_dict_name = isinstance(element, ast.Name) and element.id in dicts
            item = dicts[element.id] if is_dict_name else element
            if isinstance(item, ast.Dict):
                overrides |= {ast.literal_eval(key) for key in item.keys}
            else:
                sources.append(ast.unparse(item))
        nodes[ast.literal_eval(keywords['executable'])] = {
            'name': ast.literal_eval(keywords['name']),
            'package': ast.unparse(keywords['package']),
            'sources': sources,
            'overrides': overrides,
        }
    return nodes


def test_the_launch_file_starts_the_three_nodes_of_this_package():
    nodes = launch_nodes()
    assert set(nodes) == set(NODE_CONFIGS)
    scripts = set(
        re.findall(r"'(\w+) = id_learning\.nodes\.\w+:main'", (REPO / 'setup.py').read_text())
    )
    assert set(nodes) <= scripts
    assert {node['package'] for node in nodes.values()} == {'PACKAGE'}
    assert "PACKAGE = 'id_learning'" in LAUNCH.read_text()


def test_every_node_reads_the_one_parameter_file_and_has_its_section():
    sections = yaml.safe_load((REPO / 'config/nodes.yaml').read_text())
    for executable, node in launch_nodes().items():
        assert node['sources'] == ['params_file'], executable
        assert node['name'] in sections, f'config/nodes.yaml has no section {node["name"]}'


def test_every_parameter_the_launch_sets_is_declared_by_its_node():
    for executable, node in launch_nodes().items():
        declared = {item.name for item in dataclasses.fields(NODE_CONFIGS[executable])}
        unknown = node['overrides'] - declared - BUILT_IN
        assert not unknown, f'{executable}: the launch file sets undeclared {sorted(unknown)}'


def test_every_launch_argument_used_is_declared():
    tree = ast.parse(LAUNCH.read_text())

    def names(function: str) -> set[str]:
        return {
            call.args[0].value
            for call in _calls(tree, function)
            if call.args and isinstance(call.args[0], ast.Constant)
        }

    declared = names('DeclareLaunchArgument')
    used = names('LaunchConfiguration') | names('as_string')
    assert used <= declared, sorted(used - declared)
    assert {'bag', 'artifact', 'params_file'} <= declared
