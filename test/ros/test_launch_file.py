"""The launch file, run against stand-ins of launch and launch_ros (they are not on PyPI).

``generate_launch_description()`` runs as ``ros2 launch`` would call it; the stand-ins record
what it builds. What ``ros2 launch`` would trip over is checked against the package itself:
every node is one of the package's console scripts, reads the one parameter file and has its
section there, every parameter the launch sets is one the node declares, every launch argument
used is declared, and the replay waits for the subscriptions the launched nodes make.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

import pytest
import yaml
from support import REPO

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from id_learning.entry import PROGRAMS
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


class Recorded:
    """A stand-in of a launch class: keeps its arguments, and itself in ``made`` by class."""

    made: ClassVar[dict[str, list[Recorded]]] = {}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args, self.kwargs = args, kwargs
        Recorded.made.setdefault(type(self).__name__, []).append(self)


class LaunchConfiguration(Recorded):
    def evaluate(self, values: dict[str, str]) -> str:
        return values[self.args[0]]


class PythonExpression(Recorded):
    def evaluate(self, values: dict[str, str]) -> object:
        """Join the parts, launch configurations substituted, and evaluate: as launch does."""
        parts = self.args[0]
        return eval(''.join(p if isinstance(p, str) else p.evaluate(values) for p in parts))


STAND_INS = {
    'launch': {},
    'launch.actions': {'DeclareLaunchArgument': type('DeclareLaunchArgument', (Recorded,), {})},
    'launch.conditions': {'IfCondition': type('IfCondition', (Recorded,), {})},
    'launch.launch_description': {'LaunchDescription': type('LaunchDescription', (Recorded,), {})},
    'launch.substitutions': {
        'LaunchConfiguration': LaunchConfiguration,
        'PythonExpression': PythonExpression,
    },
    'launch_ros': {},
    'launch_ros.actions': {'Node': type('Node', (Recorded,), {})},
    'launch_ros.parameter_descriptions': {
        'ParameterValue': type('ParameterValue', (Recorded,), {})
    },
}


@pytest.fixture(scope='module')
def share(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp('share')


@pytest.fixture(scope='module')
def launched(share: Path) -> dict[str, list[Recorded]]:
    """What generate_launch_description() builds, by stand-in class name."""
    with pytest.MonkeyPatch.context() as patch:
        for name, attributes in STAND_INS.items():
            module = ModuleType(name)
            module.__dict__.update(attributes)
            patch.setitem(sys.modules, name, module)
        packages = ModuleType('ament_index_python.packages')
        packages.get_package_share_directory = lambda package: str(share / package)  # type: ignore[attr-defined]
        patch.setitem(sys.modules, 'ament_index_python.packages', packages)
        patch.setattr(Recorded, 'made', {})
        spec = importlib.util.spec_from_file_location('id_learning_launch', LAUNCH)
        assert spec is not None
        assert spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        description = module.generate_launch_description()
        made = Recorded.made
    (entities,) = description.args
    # The description holds every declared argument and every node, each once.
    built = [*made['DeclareLaunchArgument'], *made['Node']]
    assert sorted(map(id, entities)) == sorted(map(id, built))
    return made


def nodes(launched) -> dict[str, Recorded]:
    return {node.kwargs['executable']: node for node in launched['Node']}


def declared(launched) -> dict[str, Recorded]:
    return {argument.args[0]: argument for argument in launched['DeclareLaunchArgument']}


def test_the_launch_file_starts_the_three_node_scripts_of_this_package(launched):
    started = nodes(launched)
    assert set(started) == set(NODE_CONFIGS)
    scripts = {
        entry.name: entry
        for entry in importlib.metadata.distribution('id_learning').entry_points
        if entry.group == 'console_scripts'
    }
    for executable, node in started.items():
        assert node.kwargs['package'] == 'id_learning', executable
        assert node.kwargs['name'] == executable
        # The script imports the node inside Ctrl-C's handling (id_learning/entry.py).
        assert scripts[executable].value == f'id_learning.entry:{executable}', executable
        assert PROGRAMS[executable] == (f'id_learning.nodes.{executable}', 'main'), executable


def test_every_node_reads_the_one_parameter_file_and_has_its_section(launched, share):
    sections = yaml.safe_load((REPO / 'config/nodes.yaml').read_text())
    params_file = declared(launched)['params_file']
    assert params_file.kwargs['default_value'] == str(share / 'id_learning/config/nodes.yaml')
    for executable, node in nodes(launched).items():
        first, *overrides = node.kwargs['parameters']
        assert isinstance(first, LaunchConfiguration), executable
        assert first.args == ('params_file',), executable
        assert all(isinstance(item, dict) for item in overrides), executable
        assert node.kwargs['name'] in sections, f'config/nodes.yaml has no section {executable}'


def test_every_parameter_the_launch_sets_is_declared_by_its_node(launched):
    for executable, node in nodes(launched).items():
        names = {key for item in node.kwargs['parameters'][1:] for key in item}
        fields = {item.name for item in dataclasses.fields(NODE_CONFIGS[executable])}
        unknown = names - fields - BUILT_IN
        assert not unknown, f'{executable}: the launch file sets undeclared {sorted(unknown)}'


def test_every_launch_argument_used_is_declared(launched):
    arguments = declared(launched)
    used = {configuration.args[0] for configuration in launched['LaunchConfiguration']}
    assert used <= set(arguments), sorted(used - set(arguments))
    assert {'bag', 'artifact', 'params_file', 'record', 'use_sim_time'} <= used
    # Arguments without a default must be given on the command line: only bag and artifact.
    required = {name for name, a in arguments.items() if 'default_value' not in a.kwargs}
    assert required == {'bag', 'artifact'}
    (condition,) = launched['IfCondition']
    assert nodes(launched)['recorder'].kwargs['condition'] is condition
    assert condition.args[0].args == ('record',)


@pytest.mark.parametrize('record', ['true', 'false'])
@pytest.mark.parametrize('use_sim_time', ['true', 'false'])
def test_the_replay_waits_for_the_subscriptions_of_the_launched_nodes(
    launched, record, use_sim_time
):
    # The predictor subscribes to the reference, a recorder to each of its topics; with
    # use_sim_time each of them also subscribes to /clock.
    recorder_topics = yaml.safe_load((REPO / 'config/nodes.yaml').read_text())['recorder'][
        'ros__parameters'
    ]['topics']
    running = {'predictor': 1} | ({'recorder': len(recorder_topics)} if record == 'true' else {})
    expected = sum(running.values()) + (len(running) if use_sim_time == 'true' else 0)
    replay = nodes(launched)['replay']
    (overrides,) = replay.kwargs['parameters'][1:]
    wait = overrides['wait_for_subscribers']
    assert wait.kwargs['value_type'] is int
    (expression,) = wait.args
    values = {'record': record, 'use_sim_time': use_sim_time}
    assert expression.evaluate(values) == expected
