"""Replay + predictor + recorder with one parameter file (the controller stand-in chain).

    ros2 launch id_learning id_learning.launch.py bag:=bags/default \
        artifact:=out/demo/run/models/mlp output:=recordings/replayed

The replay plays ``bag`` at the IPO pace, publishes /clock and the reference; the predictor turns
each reference sample into tau_u; the recorder records the replayed topics. All three read
``params_file`` (default: the package's config/nodes.yaml); the launch arguments below override
single entries. With ``use_sim_time:=true`` predictor and recorder follow the replay's /clock
(the recorder's log times are then the bag's times).
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.launch_description import LaunchDescription
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

PACKAGE = 'id_learning'


def as_string(name: str) -> ParameterValue:
    """A launch argument passed as a string parameter (no YAML conversion: '' stays '')."""
    return ParameterValue(LaunchConfiguration(name), value_type=str)


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments and the three nodes."""
    default_params = os.path.join(get_package_share_directory(PACKAGE), 'config', 'nodes.yaml')
    params_file = LaunchConfiguration('params_file')
    use_sim_time = LaunchConfiguration('use_sim_time')
    arguments = [
        DeclareLaunchArgument(
            'params_file', default_value=default_params, description='ROS 2 parameter file.'
        ),
        DeclareLaunchArgument('bag', description='Bag folder to replay.'),
        DeclareLaunchArgument('artifact', description='Model artifact folder for the predictor.'),
        DeclareLaunchArgument(
            'output', default_value='', description="Recorder's bag folder ('' = timestamped)."
        ),
        DeclareLaunchArgument(
            'use_sim_time',
            default_value='false',
            description='Predictor and recorder follow the replay /clock.',
        ),
        DeclareLaunchArgument('record', default_value='true', description='Start the recorder.'),
    ]
    sim_time = {'use_sim_time': ParameterValue(use_sim_time, value_type=bool)}
    replay = Node(
        package=PACKAGE,
        executable='replay',
        name='replay',
        output='screen',
        parameters=[
            params_file,
            {
                'bag': as_string('bag'),
                # recorder (2 topics) + predictor (reference), and with use_sim_time their
                # /clock subscriptions: all are up before the first cycle is played.
                'wait_for_subscribers': ParameterValue(
                    PythonExpression(
                        [
                            '(1 + (2 if "',
                            LaunchConfiguration('record'),
                            '".lower() == "true" else 0)) + ((1 + (1 if "',
                            LaunchConfiguration('record'),
                            '".lower() == "true" else 0)) if "',
                            use_sim_time,
                            '".lower() == "true" else 0)',
                        ]
                    ),
                    value_type=int,
                ),
            },
        ],
    )
    predictor = Node(
        package=PACKAGE,
        executable='predictor',
        name='predictor',
        output='screen',
        parameters=[params_file, {'artifact': as_string('artifact')}, sim_time],
    )
    recorder = Node(
        package=PACKAGE,
        executable='recorder',
        name='recorder',
        output='screen',
        parameters=[params_file, {'output': as_string('output')}, sim_time],
        condition=IfCondition(LaunchConfiguration('record')),
    )
    return LaunchDescription([*arguments, recorder, predictor, replay])
