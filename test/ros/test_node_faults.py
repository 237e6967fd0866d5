"""Faults at the nodes' edges: clashing topics, timer periods that spin, a params file for another
node, publishers of another type, invalid stamps, integers for doubles, burst losses counted."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from predictor.tiny_artifacts import reference_run
from ros.ros_helpers import STARTUP_S, node_environment, random_domain

from id_learning.errors import ConfigError
from id_learning.nodes.param_ros import refuse_foreign_params_files
from id_learning.nodes.param_schema import (
    params_file_problem,
    params_files,
    section_matches,
)
from id_learning.nodes.params import (
    PredictorNodeConfig,
    RecorderConfig,
    ReplayConfig,
    config_from_mapping,
    validate_change,
)

pytestmark = pytest.mark.ros

REQUIRED = {ReplayConfig: {'bag': 'b'}, PredictorNodeConfig: {'artifact': 'a'}, RecorderConfig: {}}
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'


def build(cls, **values):
    return config_from_mapping(cls, {**REQUIRED[cls], **values}, f'node {cls.__name__}')


# -- topics that clash ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ('cls', 'values', 'match'),
    [
        (PredictorNodeConfig, {'output_topic': 'reference'}, 'input_topic and output_topic'),
        (PredictorNodeConfig, {'command_topic': 'tau_u'}, 'output_topic and command_topic'),
        (
            PredictorNodeConfig,
            {'input_topic': '/m', 'measured_topic': '/m', 'adaptation': 'rls'},
            'input_topic and measured_topic',
        ),
        (PredictorNodeConfig, {'output_topic': '/diagnostics'}, "output_topic '/diagnostics'"),
        (ReplayConfig, {'reference_topic': '/joint_states'}, 'topics.0. and reference_topic'),
        (
            ReplayConfig,
            {'topics': ['/clock']},
            "topics.0. '/clock' is the topic of the node's clock",
        ),
        (ReplayConfig, {'topics': ['/a', '/a']}, 'topics.0. and topics.1.'),
        (
            RecorderConfig,
            {'topics': ['/diagnostics'], 'msg_types': ['std_msgs/msg/String']},
            "topics.0. '/diagnostics' is the topic of the node's diagnostics",
        ),
    ],
)
def test_two_topic_parameters_on_one_topic_are_refused_naming_both(cls, values, match):
    with pytest.raises(ConfigError, match=match):
        build(cls, **values)


@pytest.mark.parametrize(
    ('cls', 'values'),
    [
        (PredictorNodeConfig, {'input_topic': '/motor_currents'}),  # adaptation off: unused
        (ReplayConfig, {'topics': ['/clock'], 'publish_clock': False}),
        (ReplayConfig, {'topics': ['/diagnostics']}),  # a bag's reports beside the replay's
        (
            RecorderConfig,
            {
                'topics': ['/joint_states', '/diagnostics'],
                'msg_types': ['sensor_msgs/msg/JointState', DIAGNOSTIC_ARRAY],
            },
        ),
    ],
)
def test_topics_that_do_not_clash_pass(cls, values):
    build(cls, **values)


def test_names_that_resolve_to_one_topic_are_refused_by_the_node(ros_context):
    from rclpy.node import Node

    from id_learning.nodes.endpoints import refuse_clashing_topics

    config = PredictorNodeConfig(artifact='a', output_topic='/reference')  # input: 'reference'
    node = Node('predictor', context=ros_context)
    try:
        with pytest.raises(
            ConfigError, match=r"node predictor: input_topic and output_topic .*'/reference'"
        ):
            refuse_clashing_topics(node, config)
    finally:
        node.destroy_node()
    elsewhere = Node('predictor', namespace='/robot', context=ros_context)
    try:
        refuse_clashing_topics(elsewhere, config)  # /robot/reference and /reference
    finally:
        elsewhere.destroy_node()
    remapped = Node(
        'predictor', context=ros_context, cli_args=['--ros-args', '-r', 'tau_u:=/reference']
    )
    try:
        with pytest.raises(ConfigError, match='input_topic and output_topic'):
            refuse_clashing_topics(remapped, PredictorNodeConfig(artifact='a'))
    finally:
        remapped.destroy_node()


def test_a_topic_rcl_refuses_is_one_line_naming_the_parameter_and_what_holds_it(ros_context):
    from rclpy.node import Node
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from id_learning.nodes.endpoints import endpoint

    node = Node('predictor', context=ros_context)
    try:
        node.create_publisher(JointState, '/tau_u', 10)
        with pytest.raises(ConfigError) as raised, endpoint(node, 'command_topic', 'tau_u'):
            node.create_publisher(Float64MultiArray, 'tau_u', 10)
        text = str(raised.value)
        assert text.startswith("node predictor: command_topic 'tau_u': ROS 2 refused the topic")
        assert 'a publisher of sensor_msgs/msg/JointState on /tau_u' in text
        assert '\n' not in text
        assert '/project/src' not in text  # rcl's source locations left out
    finally:
        node.destroy_node()


# -- periods that spin a CPU ----------------------------------------------------------------------
@pytest.mark.parametrize('cls', [RecorderConfig, ReplayConfig, PredictorNodeConfig])
@pytest.mark.parametrize('period', [1e-6, 0.049, 3601.0])
def test_a_diagnostics_period_that_would_spin_or_overflow_is_refused_at_start_and_at_runtime(
    cls, period
):
    with pytest.raises(
        ConfigError, match=r'diagnostics_period_s: must be a finite number in \[0.05'
    ):
        build(cls, diagnostics_period_s=period)
    changed, reason = validate_change(build(cls), {'diagnostics_period_s': period})
    assert changed is None
    assert 'diagnostics_period_s' in reason
    assert build(cls, diagnostics_period_s=0.05).diagnostics_period_s == 0.05


@pytest.mark.parametrize(
    ('values', 'match'),
    [
        ({'flush_period_s': 1e-6}, r'flush_period_s: must be a finite number in \[0.01, 0.5\]'),
        ({'split_duration_s': 1e-6}, 'split_duration_s: must be 0 .off. or at least 0.1 s'),
        ({'split_size_mib': 1e-6}, 'split_size_mib: must be 0 .off. or at least 0.1 MiB'),
    ],
)
def test_recorder_periods_and_splits_that_spin_are_refused(values, match):
    with pytest.raises(ConfigError, match=match):
        build(RecorderConfig, **values)


def test_the_stale_line_repeats_at_most_once_a_second():
    refused = r'stale_log_period_s: must be 0 \(once\) or at least 1 s'
    with pytest.raises(ConfigError, match=refused):
        build(PredictorNodeConfig, stale_log_period_s=1e-6)
    changed, reason = validate_change(build(PredictorNodeConfig), {'stale_log_period_s': 0.5})
    assert changed is None
    assert 'stale_log_period_s' in reason
    assert build(PredictorNodeConfig, stale_log_period_s=0.0).stale_log_period_s == 0.0


# -- a params file for another node ---------------------------------------------------------------
@pytest.mark.parametrize(
    ('key', 'node', 'namespace', 'matches'),
    [
        ('recorder', 'recorder', '/', True),
        ('/recorder', 'recorder', '/', True),
        ('/**', 'recorder', '/robot', True),
        ('**', 'recorder', '/', True),
        ('/*', 'recorder', '/', True),
        ('/**/recorder', 'recorder', '/a/b', True),
        ('/robot/*', 'recorder', '/robot', True),
        ('/robot/recorder', 'recorder', '/robot', True),
        ('recorder', 'recorder', '/robot', True),  # the bare name, leniently
        ('recordr', 'recorder', '/', False),
        ('/other/recorder', 'recorder', '/robot', False),
        ('/*', 'recorder', '/robot', False),
        ('predictor', 'recorder', '/', False),
    ],
)
def test_params_file_sections_match_nodes_by_rcls_rules(key, node, namespace, matches):
    assert section_matches(key, node, namespace) is matches


def test_a_params_file_without_the_nodes_section_is_named_with_the_closest():
    problem = params_file_problem(Path('p.yaml'), {'recordr': {}, 'replay': {}}, 'recorder')
    assert problem is not None
    assert problem.startswith('p.yaml: no section of it is for node /recorder')
    assert 'did you mean recorder for recordr?' in problem
    assert "['recordr', 'replay']" in problem
    assert params_file_problem(Path('p.yaml'), {'/**': {}}, 'recorder') is None


def test_the_command_line_gives_its_params_files():
    args = ['x', '--ros-args', '--params-file', 'a.yaml', '-p', 'x:=1', '--params-file', 'b.yaml',
            '--', '--params-file', 'not_ros.yaml', '--ros-args', '--params-file']  # fmt: skip
    assert params_files(args) == [Path('a.yaml'), Path('b.yaml')]
    assert params_files([]) == []


def test_a_node_refuses_a_params_file_without_its_section_by_its_resolved_name(
    ros_context, tmp_path
):
    from rclpy.node import Node

    path = tmp_path / 'p.yaml'
    path.write_text('/robot/rec:\n  ros__parameters:\n    output: x\n')
    args = ['--ros-args', '--params-file', str(path)]
    remapped = Node('recorder', context=ros_context, cli_args=['--ros-args', '-r', '__node:=rec',
                                                               '-r', '__ns:=/robot'])  # fmt: skip
    try:
        refuse_foreign_params_files(remapped, args)
    finally:
        remapped.destroy_node()
    node = Node('recorder', context=ros_context)
    try:
        with pytest.raises(ConfigError, match=r'node recorder: .*p.yaml: no section of it is for '
                                              r'node /recorder'):  # fmt: skip
            refuse_foreign_params_files(node, args)
    finally:
        node.destroy_node()


def test_a_node_refuses_a_params_file_that_gives_a_key_twice_naming_it_and_both_lines(
    ros_context, tmp_path
):
    """rcl keeps the later value without a word; the package's YAML readers refuse it."""
    from rclpy.node import Node

    path = tmp_path / 'p.yaml'
    path.write_text('predictor:\n  ros__parameters:\n    artifact: a\n    torque_rise_s: 0.05\n'
                    '    torque_rise_s: 5.0\n')  # fmt: skip
    broken = tmp_path / 'broken.yaml'
    broken.write_text('predictor:\n  ros__parameters:\n    artifact: [a\n')
    node = Node('predictor', context=ros_context)
    try:
        twice = r"node predictor: --params-file .*p.yaml: duplicate key 'torque_rise_s' at "
        twice += 'lines 4 and 5'
        with pytest.raises(ConfigError, match=twice):
            refuse_foreign_params_files(node, ['--ros-args', '--params-file', str(path)])
        with pytest.raises(ConfigError, match=r'broken.yaml: not valid YAML'):
            refuse_foreign_params_files(node, ['--ros-args', '--params-file', str(broken)])
        path.write_text('predictor:\n  ros__parameters:\n    torque_rise_s: 0.05\n'
                        'replay:\n  ros__parameters:\n    torque_rise_s: 0.05\n')  # fmt: skip
        refuse_foreign_params_files(node, ['--ros-args', '--params-file', str(path)])  # apart
    finally:
        node.destroy_node()


# -- integers for doubles -------------------------------------------------------------------------
@pytest.fixture
def ros_context():
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=random_domain())
    try:
        yield context
    finally:
        context.try_shutdown()


def test_an_integer_for_a_double_parameter_stays_a_double_at_start_and_at_runtime(ros_context):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from id_learning.nodes.params import declare_parameters, read_snapshot

    overrides = [Parameter('artifact', value='a'), Parameter('max_age_s', value=1)]
    node = Node('predictor', context=ros_context, parameter_overrides=overrides)
    try:
        declare_parameters(node, PredictorNodeConfig)
        assert node.get_parameter('max_age_s').type_ == Parameter.Type.DOUBLE
        assert read_snapshot(node, PredictorNodeConfig).max_age_s == 1.0
        result = node.set_parameters([Parameter('torque_limit_scale', value=1)])[0]
        assert result.successful, result.reason
        changed = node.get_parameter('torque_limit_scale')
        assert changed.type_ == Parameter.Type.DOUBLE
        assert changed.value == 1.0
        assert node.get_parameter('input_depth').type_ == Parameter.Type.INTEGER  # untouched
    finally:
        node.destroy_node()


# -- refused at start, in one line ----------------------------------------------------------------
def test_nodes_refuse_clashing_topics_and_a_params_file_for_another_node_in_one_line(tmp_path):
    (tmp_path / 'typo.yaml').write_text('recordr:\n  ros__parameters:\n    output: mine\n')
    (tmp_path / 'twice.yaml').write_text('recorder:\n  ros__parameters:\n    output: mine\n'
                                         '    output: yours\n')  # fmt: skip
    # One predictor only (it imports torch: seconds); the same checks run in-process above.
    cases = {
        'output_on_input': ('predictor', ['-p', 'artifact:=a', '-p', 'output_topic:=/reference'],
                            "input_topic and output_topic both name topic '/reference'"),
        'recorder_typo': ('recorder', ['--params-file', 'typo.yaml'],
                          'typo.yaml: no section of it is for node /recorder (did you mean '
                          'recorder for recordr?)'),
        'recorder_twice': ('recorder', ['--params-file', 'twice.yaml'],
                           "--params-file twice.yaml: duplicate key 'output' at lines 3 and 4"),
        'rosout_as_string': ('recorder', ['-p', 'output:=rosout', '-p', "topics:=['/rosout']",
                                          '-p', "msg_types:=['std_msgs/msg/String']"],
                             "topics[0] '/rosout': ROS 2 refused the topic"),
    }  # fmt: skip
    env = node_environment(random_domain())
    started = {
        case: subprocess.Popen(
            [sys.executable, '-m', f'id_learning.nodes.{module}', '--ros-args', *arguments],
            env=env,
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for case, (module, arguments, _) in cases.items()
    }
    try:
        outputs = {case: process.communicate(timeout=120) for case, process in started.items()}
    finally:
        for process in started.values():
            if process.poll() is None:
                process.kill()
                process.wait(10)
    for case, (_, _, message) in cases.items():
        stdout, stderr = outputs[case]
        assert started[case].returncode == 2, (case, stderr)
        assert f'error: node {cases[case][0]}: {message}' in stderr, (case, stderr)
        assert 'Traceback' not in stdout + stderr, (case, stderr)
    # Refused before anything was written: no bag, neither the file's nor the default one.
    assert sorted(path.name for path in tmp_path.iterdir()) == ['twice.yaml', 'typo.yaml']


# -- the predictor names what it cannot take and counts what it lost ------------------------------
def test_predictor_names_a_foreign_publisher_refuses_invalid_stamps_and_counts_bursts(
    nodes, listener, domain_id, tiny_artifacts, mabi
):
    import rclpy
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from id_learning.nodes.qos import reference_qos

    listener.subscribe(DiagnosticArray, '/diagnostics')
    publisher = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(100))
    # Another participant (one cannot have two types on one topic); it needs no spinning.
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    sender = rclpy.create_node('foreign_sender', context=context)
    foreign = sender.create_publisher(JointState, '/reference', 10)
    predictor = nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts['mlp']),
            'input_topic': '/reference',
            'diagnostics_period_s': 0.05,
            'consistency_scale': 1000.0,
        },
    )

    def diagnostics():
        return listener.diagnostics('id_learning/predictor') or {}

    def named() -> bool:
        return '/foreign_sender sensor_msgs/msg/JointState on /reference' in diagnostics().get(
            'wrong_type_publishers', ''
        )

    listener.wait_for(named, STARTUP_S, 'the foreign publisher named on /diagnostics')
    listener.wait_for(lambda: publisher.get_subscription_count() >= 1, STARTUP_S, 'the predictor')
    with listener.condition:
        messages = [
            status.message
            for msg in listener.messages['/diagnostics']
            for status in msg.status
            if status.name == 'id_learning/predictor'
        ]
    assert any('input_type joint_state would take it (now trajectory)' in m for m in messages)
    sender.destroy_publisher(foreign)
    sender.destroy_node()
    context.try_shutdown()

    _, q, v, a = reference_run(150)
    joints = list(mabi.joints)

    def message(k: int, sec: int, nanosec: int) -> JointTrajectory:
        point = JointTrajectoryPoint(positions=list(q[k]), velocities=list(v[k]),
                                     accelerations=list(a[k]))  # fmt: skip
        msg = JointTrajectory(joint_names=joints, points=[point])
        msg.header.stamp = Time(sec=sec, nanosec=nanosec)
        return msg

    start_ns = time.time_ns()
    for burst in range(3):  # 50 references at once, every 50 periods
        for k in range(50 * burst, 50 * burst + 50):
            publisher.publish(message(k, *divmod(start_ns + k * 8_000_000, 1_000_000_000)))
        time.sleep(0.4)  # the sender's own pace (its bursts), not synchronisation
    for nanosec in (1_500_000_000, 1_000_000_000, 4_000_000_000):
        publisher.publish(message(0, 100, nanosec))
    for _ in range(2):
        publisher.publish(message(0, -5, 0))
    listener.wait_for(
        lambda: diagnostics().get('rejected_invalid_stamp') == '5', 30, 'five invalid stamps'
    )
    values = diagnostics()
    valid = int(values['received']) - 5
    # Each burst's newest reference is taken; the queue (10 deep) overwrote most of the others.
    assert valid < 150
    assert 101 <= valid + int(values['skipped_cycles']) <= 150, values
    assert int(values['skipped_cycles_in_holes']) > 0
    assert int(values['rejected']) >= 5
    assert predictor.stop() == 0
    log = predictor.log()
    assert (
        log.count('node /foreign_sender publishes sensor_msgs/msg/JointState on /reference') == 1
    )
    assert 'no model torque (invalid_stamp): header stamp nanosec 1500000000 is not in' in log
    assert "'invalid_stamp': 5" in log


# -- a bag with invalid stamps --------------------------------------------------------------------
@pytest.mark.parametrize(('sec', 'nanosec'), [(5, 1_500_000_000), (-5, 0)])
@pytest.mark.parametrize('timing', ['stamp', 'log_time'])
def test_the_replay_refuses_a_bag_whose_stamps_are_no_time(tmp_path, mabi, sec, nanosec, timing):
    from support import sine_recording

    from id_learning.bag import BagWriter, iter_raw
    from id_learning.bag.messages import typestore
    from id_learning.dataset.recording import write_recording
    from id_learning.errors import BagError
    from id_learning.nodes.replay import build_plan

    source = write_recording(sine_recording(50), tmp_path / 'source')
    store = typestore()
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/motor_currents', 'sensor_msgs/msg/JointState')
        states = 0
        for topic, log_ns, data in iter_raw(source, ['/joint_states', '/motor_currents']):
            states += topic == '/joint_states'
            written = data
            if topic == '/joint_states' and states == 10:
                msg = store.deserialize_cdr(data, 'sensor_msgs/msg/JointState')
                msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
                written = store.serialize_cdr(msg, 'sensor_msgs/msg/JointState')
            writer.write(topic, log_ns, written)
    config = ReplayConfig(bag=str(tmp_path / 'bag'), timing=timing)
    with pytest.raises(BagError, match=r'/joint_states message 9: invalid header stamp: '):
        build_plan(config, mabi)
