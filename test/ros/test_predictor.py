"""predictor, in its own process: online tau_u equals the offline prediction; guards hold."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from predictor.tiny_artifacts import reference_run
from ros.ros_helpers import STARTUP_S
from support import sine_recording

from id_learning.bag import read_joint_states
from id_learning.dataset.recording import write_recording
from id_learning.models.registry import STUDY_MODELS, load_model
from id_learning.predictor import causal_acceleration

pytestmark = pytest.mark.ros

N_SAMPLES = 80


def tau_u_subscriptions(listener, name: str) -> int:
    """Subscriptions matched by a predictor's tau_u publisher, from its diagnostics."""
    return int((listener.diagnostics(name) or {}).get('tau_u_subscriptions', 0))


def wait_connected(listener, publisher) -> None:
    """Until the predictor takes our reference and its tau_u publisher has matched us."""
    listener.wait_for(
        lambda: (
            publisher.get_subscription_count() >= 1
            and tau_u_subscriptions(listener, 'id_learning/predictor') >= 1
        ),
        STARTUP_S,
        'the predictor to connect (both ways)',
    )


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_replay_to_predictor_gives_the_offline_prediction_for_every_model_kind(
    tmp_path, nodes, listener, tiny_artifacts, mabi
):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory

    bag = write_recording(sine_recording(N_SAMPLES), tmp_path / 'bag')
    namespaces = {kind: f'/{kind}' for kind in STUDY_MODELS}
    listener.subscribe(JointTrajectory, '/reference')
    for kind in STUDY_MODELS:
        listener.subscribe(JointState, f'/{kind}/tau_u')
    listener.subscribe(JointState, '/mlp_js/tau_u')
    common = {'input_depth': 100, 'input_topic': '/reference', 'diagnostics_period_s': 0.2}
    for kind, namespace in namespaces.items():
        nodes(
            'predictor',
            {'artifact': str(tiny_artifacts[kind]), **common},
            name=f'predictor_{kind}',
            remaps={'__ns': namespace},
        )
    # The same MLP on the raw joint states: accelerations estimated causally.
    nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts['mlp']),
            'input_type': 'joint_state',
            'input_topic': '/joint_states',
            'input_depth': 100,
            'diagnostics_period_s': 0.2,
        },
        name='predictor_mlp_js',
        remaps={'__ns': '/mlp_js'},
    )
    listener.subscribe(DiagnosticArray, '/diagnostics')
    # Every predictor's tau_u publisher has matched the listener (writer side): none of its
    # outputs can be lost to discovery. The replay waits for its own subscribers.
    for namespace in [*namespaces.values(), '/mlp_js']:
        listener.wait_for(
            lambda ns=namespace: tau_u_subscriptions(listener, f'id_learning{ns}/predictor') >= 1,
            STARTUP_S,
            f'the predictor in {namespace} to connect',
        )
    replay = nodes(
        'replay',
        {
            'bag': str(bag),
            'rate': 0.5,
            'reference_topic': '/reference',
            'wait_for_subscribers': len(STUDY_MODELS) + 2,
        },
    )
    assert replay.wait(120) == 0

    topics = [f'/{kind}/tau_u' for kind in STUDY_MODELS] + ['/mlp_js/tau_u']
    listener.wait_for(
        lambda: (
            all(len(listener.messages[t]) >= N_SAMPLES for t in topics)
            and len(listener.messages['/reference']) >= N_SAMPLES
        ),
        60,
        f'{N_SAMPLES} tau_u messages from each predictor',
    )
    with listener.condition:
        reference = sorted(listener.messages['/reference'], key=stamp_ns)
        outputs = {t: list(listener.messages[t]) for t in topics}

    states = read_joint_states(bag, '/joint_states')
    assert [stamp_ns(m) for m in reference] == states.stamps_ns.tolist()
    names = list(reference[0].joint_names)
    assert names == list(mabi.joints)
    q = np.array([m.points[0].positions for m in reference])
    v = np.array([m.points[0].velocities for m in reference])
    a = np.array([m.points[0].accelerations for m in reference])
    limit = mabi.limits.torque

    def check(topic: str, expected: np.ndarray, stamps: list[int]) -> None:
        got = outputs[topic]
        assert len(got) == N_SAMPLES, topic  # one tau_u per input sample
        assert [stamp_ns(m) for m in got] == stamps, topic  # stamped with the input stamps
        assert all(list(m.name) == names for m in got), topic
        effort = np.array([m.effort for m in got])
        scale = np.abs(expected).max()
        assert scale > 0
        np.testing.assert_allclose(effort, expected, rtol=1e-5, atol=1e-6 * scale, err_msg=topic)

    stamps = [stamp_ns(m) for m in reference]
    for kind in STUDY_MODELS:
        model = load_model(tiny_artifacts[kind], mabi)
        check(f'/{kind}/tau_u', np.clip(model.predict(q, v, a), -limit, limit), stamps)
    a_causal = causal_acceleration(states.stamps_ns, states.velocity)
    mlp = load_model(tiny_artifacts['mlp'], mabi)
    expected = np.clip(mlp.predict(states.position, states.velocity, a_causal), -limit, limit)
    check('/mlp_js/tau_u', expected, states.stamps_ns.tolist())


#: The bad-input test's output limit, as a share of the robot's (so that hard but possible
#: accelerations are clamped).
LIMIT_SCALE = 0.3


def test_predictor_survives_bad_input_publishes_nothing_invalid_and_counts_it(
    nodes, listener, tiny_artifacts, mabi
):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from id_learning.nodes.qos import reference_qos

    kind = 'rnea_lq'
    listener.subscribe(JointState, '/tau_u')
    listener.subscribe(Float64MultiArray, '/ff/commands')
    listener.subscribe(DiagnosticArray, '/diagnostics')
    publisher = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(100))
    predictor = nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts[kind]),
            'input_topic': '/reference',
            'input_depth': 100,
            'stale_after_cycles': 25,
            'max_age_s': 0.5,
            # The stamps are send times, not the motion's (q, v, a at 8 ms steps): the
            # consistency gate (test_stream_properties.py) is not what this test checks.
            'consistency_scale': 1000.0,
            'diagnostics_period_s': 0.1,
            'log_throttle_s': 0.2,
            'command_topic': '/ff/commands',
            'torque_limit_scale': LIMIT_SCALE,
        },
    )
    wait_connected(listener, publisher)
    joints = list(mabi.joints)
    _, q, v, a = reference_run(20)
    limit = LIMIT_SCALE * mabi.limits.torque
    a_big = 1.9 * mabi.limits.acceleration  # hard, but within what an arm can do (2x)
    a_impossible = np.full(6, 1e4)  # far beyond the robot's acceleration limits
    model = load_model(tiny_artifacts[kind], mabi)
    raw = model.predict(q[10:14], v[10:14], np.tile(a_big, (4, 1)))
    assert np.all(np.any(np.abs(raw) > limit, axis=1))  # precondition: these will be clamped
    normal = model.predict(q, v, a)
    assert np.all(np.abs(normal) < limit)  # and the others will not
    sent_ok: list[int] = []

    def send(k, *, names=joints, q_k=None, v_k=None, a_k=None, age_s=0.0, valid=True):
        msg = JointTrajectory(joint_names=list(names))
        stamp = time.time_ns() - round(age_s * 1e9)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        msg.points = [
            JointTrajectoryPoint(
                positions=list(q[k] if q_k is None else q_k),
                velocities=list(v[k] if v_k is None else v_k),
                accelerations=list(a[k] if a_k is None else a_k),
            )
        ]
        publisher.publish(msg)
        if valid:
            sent_ok.append(stamp)
        time.sleep(0.008)  # the stream's own pace (8 ms IPO), not synchronisation

    for k in range(10):
        send(k)
    for k in range(3):
        send(k, q_k=[np.nan, *q[k][1:]], valid=False)
    for k in range(2):
        send(k, v_k=[*v[k][:5], np.inf], valid=False)
    for k in range(3):
        send(k, names=joints[:5], q_k=q[k][:5], v_k=v[k][:5], a_k=a[k][:5], valid=False)
    for k in range(3):
        send(k, names=[*joints[:5], 'joint_7'], valid=False)
    for k in range(4):
        send(10 + k, a_k=a_big)
    for k in range(3):
        send(k, age_s=5.0, valid=False)
    for k in range(2):
        send(k, a_k=a_impossible, valid=False)

    def diagnostics():
        return listener.diagnostics('id_learning/predictor') or {}

    listener.wait_for(lambda: diagnostics().get('stale') == 'True', 30, 'the stale report')
    published_while_stale = len(listener.messages['/tau_u'])
    with listener.condition:
        stale_reports = [
            status.level
            for msg in listener.messages['/diagnostics']
            for status in msg.status
            if status.name == 'id_learning/predictor'
            and status.message.startswith('reference stale')
        ]
    assert stale_reports
    assert set(stale_reports) == {DiagnosticStatus.WARN}
    # The command ramps to zero while stale (at most 7 cycles from the limit): then resume.
    listener.wait_for(
        lambda: any(not any(m.data) for m in listener.messages['/ff/commands']),
        10,
        'the command ramp to reach zero',
    )
    for k in range(10, 20):
        send(k)

    expected = {
        'received': 40,
        'published': 24,
        'rejected_non_finite': 5,
        'rejected_joint_count': 3,
        'rejected_joint_names': 3,
        'rejected_too_old': 3,
        'rejected_impossible': 2,
        'rejected': 16,
        'clamped_samples': 4,
        'out_of_range_samples': 4,
    }
    listener.wait_for(
        lambda: (
            all(diagnostics().get(key) == str(value) for key, value in expected.items())
            and diagnostics().get('stale') == 'False'
            and len(listener.messages['/tau_u']) >= 24
        ),
        30,
        f'diagnostics to count {expected}',
    )
    assert predictor.is_running
    values = diagnostics()
    assert int(values['stale_episodes']) >= 1
    assert int(values['history_resets']) >= 1
    assert values['rejected_stamp_order'] == '0'
    assert int(values['skipped_cycles']) >= 0  # timing-dependent here; counted in the core tests
    assert int(values['late_samples']) >= 0
    assert values['callback_errors'] == '0'
    assert published_while_stale == 14

    with listener.condition:
        published = list(listener.messages['/tau_u'])
    assert len(published) == 24
    assert [stamp_ns(m) for m in published] == sent_ok
    for msg in published:
        assert list(msg.name) == joints
        effort = np.array(msg.effort)
        assert np.isfinite(effort).all()
        assert np.all(np.abs(effort) <= limit)
    clamped = np.array([m.effort for m in published[10:14]])
    assert np.any(np.isclose(np.abs(clamped), limit), axis=1).all()
    # The forward-command copy: tau_u, at most one period's worth of the slew limit per message
    # (torque_rise_s 0.05 s), ramped to exactly zero when stale and back towards tau_u after,
    # which it has rejoined by the last sample.
    listener.wait_for(
        lambda: (
            len(listener.messages['/ff/commands']) > len(published)
            and list(listener.messages['/ff/commands'][-1].data) == list(published[-1].effort)
        ),
        10,
        'the command copies',
    )
    with listener.condition:
        commands = np.array([list(m.data) for m in listener.messages['/ff/commands']])
    step = mabi.limits.torque / 0.05 * mabi.ipo_period_s
    assert (np.abs(np.diff(commands, axis=0)) <= step * (1 + 1e-12)).all()
    assert len(commands) > len(published)  # the ramp's commands besides one per tau_u
    assert any(not c.any() for c in commands)
    np.testing.assert_array_equal(commands[-1], published[-1].effort)
    assert predictor.stop() == 0
    log = predictor.log()
    assert 'no model torque (non_finite)' in log
    # Stale: at most one warning per episode (the slow repeat is a minute away; an episode the
    # next sample ends before the watchdog runs is counted, not logged), resumed silently.
    episodes = int(re.search(r'(\d+) stale episodes', log).group(1))
    assert 1 <= log.count('reference stale: no valid sample') <= episodes
    assert 'still stale' not in log
    assert 'resumed' not in log


def test_far_outside_its_envelope_a_network_publishes_the_physics_torque_and_counts_it(
    nodes, listener, tiny_artifacts, mabi
):
    import pinocchio as pin
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from support import REPO
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from id_learning.nodes.qos import reference_qos
    from id_learning.predictor import training_range

    listener.subscribe(JointState, '/tau_u')
    listener.subscribe(DiagnosticArray, '/diagnostics')
    publisher = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(100))
    predictor = nodes(
        'predictor',
        {
            'artifact': str(tiny_artifacts['mlp']),  # out_of_range: auto -> fallback
            'input_topic': '/reference',
            'input_depth': 100,
            'stale_after_cycles': 500,
            'max_age_s': 0.0,  # the samples below are sent at once, their stamps 10 s apart
            'diagnostics_period_s': 0.1,
        },
    )
    wait_connected(listener, publisher)
    model = load_model(tiny_artifacts['mlp'], mabi)
    low, high = training_range(model.fitted_metadata(), mabi).bounds['v']
    _, q, v, a = reference_run(6)
    far_v = v.copy()
    far_v[2:4, 1] = high[1] + 0.5 * (high[1] - low[1])  # joint_2 a half range faster
    # Each sample a history of its own (a hole between them): the speed-up of joint_2 below is
    # no motion, and within one history the consistency gate would hold it.
    stamps = [1_000_000_000 + 10_000_000_000 * k for k in range(6)]
    for k in range(6):
        msg = JointTrajectory(joint_names=list(mabi.joints))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamps[k], 1_000_000_000)
        point = JointTrajectoryPoint(
            positions=list(q[k]), velocities=list(far_v[k]), accelerations=list(a[k])
        )
        msg.points = [point]
        publisher.publish(msg)
    listener.wait_for(lambda: len(listener.messages['/tau_u']) >= 6, 30, 'six tau_u')
    listener.wait_for(
        lambda: (
            (listener.diagnostics('id_learning/predictor') or {}).get('fallback_samples') == '2'
        ),
        10,
        'diagnostics to count two samples served by the physics prior',
    )
    with listener.condition:
        effort = np.array([m.effort for m in sorted(listener.messages['/tau_u'], key=stamp_ns)])
    assert np.isfinite(effort).all()
    urdf = pin.buildModelFromUrdf(str(REPO / 'urdf/mabi_max100.urdf'))
    rotor = mabi.drives.rotor_inertia * mabi.drives.gear_ratio**2
    for k in (2, 3):
        expected = pin.rnea(urdf, urdf.createData(), q[k], far_v[k], a[k]) + rotor * a[k]
        np.testing.assert_allclose(effort[k], expected, rtol=1e-9, atol=1e-6)
    inside = [0, 1, 4, 5]
    expected = model.predict(q[inside], v[inside], a[inside])
    np.testing.assert_allclose(effort[inside], expected, rtol=1e-5, atol=1e-6)
    values = listener.diagnostics('id_learning/predictor')
    assert values['out_of_range_action'] == 'fallback'
    assert values['out_of_range_samples'] == '2'
    assert 'nominal model' in values['fallback']
    assert predictor.stop() == 0
    assert 'physics share 1.00' in predictor.log()


def test_adaptation_learns_a_friction_offset_from_the_currents_and_saves_it_beside(
    nodes, listener, tiny_artifacts, mabi, tmp_path
):
    """The currents carry 40 N*m on joint_1 more than the model: the node learns it online."""
    import json
    import shutil

    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from id_learning.nodes.qos import reference_qos

    artifact = tmp_path / 'rnea_lq'
    shutil.copytree(tiny_artifacts['rnea_lq'], artifact)
    listener.subscribe(JointState, '/tau_u')
    listener.subscribe(DiagnosticArray, '/diagnostics')
    reference = listener.node.create_publisher(JointTrajectory, '/reference', reference_qos(500))
    currents = listener.node.create_publisher(JointState, '/motor_currents', reference_qos(500))
    predictor = nodes(
        'predictor',
        {
            'artifact': str(artifact),
            'input_topic': '/reference',
            'input_depth': 500,
            'stale_after_cycles': 5000,
            # One sample per tau_u: a loaded machine sends slower than the stamps advance.
            'max_age_s': 0.0,
            'diagnostics_period_s': 0.1,
            'adaptation': 'rls',
            'adaptation_time_constant_s': 5.0,
        },
    )
    wait_connected(listener, reference)
    listener.wait_for(
        lambda: currents.get_subscription_count() >= 1, STARTUP_S, 'the currents subscription'
    )
    model = load_model(artifact, mabi)
    n = 300
    stamps, q, v, a = reference_run(n)
    tau = model.predict(q, v, a)
    extra = np.zeros(6)
    extra[0] = 40.0
    per_ampere = mabi.drives.gear_ratio * mabi.drives.torque_constant
    for k in range(n):
        msg = JointTrajectory(joint_names=list(mabi.joints))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamps[k]), 1_000_000_000)
        msg.points = [
            JointTrajectoryPoint(
                positions=list(q[k]), velocities=list(v[k]), accelerations=list(a[k])
            )
        ]
        reference.publish(msg)
        listener.wait_for(
            lambda k=k: len(listener.messages['/tau_u']) > k, 10, f'tau_u of sample {k}'
        )
        measured = JointState(name=list(mabi.joints), effort=list((tau[k] + extra) / per_ampere))
        measured.header = msg.header
        currents.publish(measured)
    listener.wait_for(
        lambda: (
            int((listener.diagnostics('id_learning/predictor') or {}).get('adaptation_updates', 0))
            >= n - 5
        ),
        10,
        'the adaptation to learn from the currents',
    )
    values = listener.diagnostics('id_learning/predictor')
    learnt = sum(
        float(values[f'adapted_{column}_joint_1'])
        * (np.tanh(v[-1, 0] / 0.01) if column.startswith('coulomb') else
           v[-1, 0] if column.startswith('viscous') else 1.0)
        for column in ('coulomb_level_nm', 'viscous_nms_per_rad', 'offset_nm')
    )  # fmt: skip
    assert learnt == pytest.approx(40.0, abs=4.0)
    assert abs(float(values['adapted_offset_nm_joint_2'])) < 1.0
    with listener.condition:
        last = sorted(listener.messages['/tau_u'], key=stamp_ns)[-1]
    assert last.effort[0] - tau[-1, 0] == pytest.approx(40.0, abs=4.0)
    assert predictor.stop() == 0
    saved = tmp_path / 'rnea_lq.adaptation.json'
    state = json.loads(saved.read_text())
    assert state['joints'] == list(mabi.joints)
    assert state['updates'] >= n - 5
    assert sorted(p.name for p in artifact.iterdir()) == sorted(
        p.name for p in tiny_artifacts['rnea_lq'].iterdir()
    )


def test_adaptation_learns_from_a_replayed_bag_whose_currents_precede_each_reference(
    nodes, listener, tiny_artifacts, mabi, tmp_path
):
    """The replay publishes each cycle's /motor_currents before its /reference: still paired.

    The bag's currents carry 40 N*m on joint_1 more than the model: the predictor learns it.
    """
    import dataclasses
    import shutil

    from diagnostic_msgs.msg import DiagnosticArray

    artifact = tmp_path / 'rnea_lq'
    shutil.copytree(tiny_artifacts['rnea_lq'], artifact)
    model = load_model(artifact, mabi)
    n = 400
    recording = sine_recording(n)
    a = np.gradient(recording.velocity, 0.008, axis=0)
    tau = model.predict(recording.position, recording.velocity, a)
    extra = np.zeros(6)
    extra[0] = 40.0
    per_ampere = mabi.drives.gear_ratio * mabi.drives.torque_constant
    bag = write_recording(
        dataclasses.replace(recording, current=(tau + extra) / per_ampere), tmp_path / 'bag'
    )
    listener.subscribe(DiagnosticArray, '/diagnostics')
    predictor = nodes(
        'predictor',
        {
            'artifact': str(artifact),
            'input_topic': '/reference',
            'input_depth': 100,
            'diagnostics_period_s': 0.1,
            'adaptation': 'rls',
            'adaptation_time_constant_s': 5.0,
        },
    )
    replay = nodes(
        'replay',
        {
            'bag': str(bag),
            'reference_topic': '/reference',
            'publish_clock': False,
            'wait_for_subscribers': 2,  # the predictor's reference and currents
            'wait_timeout_s': STARTUP_S,
        },
    )
    assert replay.wait(120) == 0

    def diagnostics() -> dict:
        return listener.diagnostics('id_learning/predictor') or {}

    listener.wait_for(
        lambda: int(diagnostics().get('adaptation_updates', 0)) >= n - 10,
        30,
        'the adaptation to learn from the replayed currents',
    )
    values = diagnostics()
    assert int(values['adaptation_unpaired']) <= 2, values
    learnt = float(values['adapted_offset_nm_joint_1'])
    assert learnt + float(values['adapted_coulomb_level_nm_joint_1']) > 20.0, values
    assert predictor.stop() == 0
    assert 'adaptation pairs no currents' not in predictor.log()
