"""The label against the URDF's gravity torque: sign and scale mistakes are named per joint."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import REPO, sine_recording, twin_config

from id_learning.dataset.content import (
    NOMINAL_SLOPE_FACTOR,
    check_content,
    gravity_findings,
    nominal_findings,
    sign_findings,
)
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.recording import Recording, load_recording, write_recording
from id_learning.physics.rigid_body import RigidBodyDynamics, build_pinocchio_model
from id_learning.robot.drives import current_from_motor_torque

#: The joints of the MABI arm whose gravity torque varies over ``sine_recording``'s motion.
LOADED = ('joint_2', 'joint_3')


def nominal_recording(robot, *, up: float = 9.81, seed: int = 0) -> Recording:
    """Currents of the nominal gravity torque (``up``: g along -z), friction and noise."""
    recording = sine_recording(2000)
    gravity = np.array([0.0, 0.0, -up])
    model = RigidBodyDynamics(build_pinocchio_model(robot), robot.joints, gravity)
    rng = np.random.default_rng(seed)
    friction = 0.02 * robot.limits.torque * np.tanh(recording.velocity / 0.01)
    tau = model.gravity(recording.position) + friction
    tau += 0.005 * robot.limits.torque * rng.standard_normal(tau.shape)
    return replace(recording, current=current_from_motor_torque(tau, robot.drives))


def gravity_of(robot):
    """The robot's URDF gravity torque, as the CLI and the trainer hand it to the checks."""
    return RigidBodyDynamics.from_config(robot).gravity


def kinds(findings) -> dict[str, str]:
    return {finding.joint: finding.kind for finding in findings}


def test_a_clean_recording_raises_no_finding(mabi) -> None:
    recording = nominal_recording(mabi)
    assert gravity_findings(recording.position, recording.current, mabi, gravity_of(mabi)) == []


def test_one_joint_with_its_current_sign_flipped_is_named_with_both_causes(mabi) -> None:
    recording = nominal_recording(mabi)
    current = recording.current.copy()
    current[:, 2] *= -1
    findings = gravity_findings(recording.position, current, mabi, gravity_of(mabi))
    assert kinds(findings) == {'joint_3': 'nominal_sign'}
    text = findings[0].text
    assert 'joint_3' in text
    assert 'sign of this joint is flipped' in text
    assert 'upside down' in text


def test_a_robot_mounted_upside_down_flips_every_judged_joint(mabi) -> None:
    recording = nominal_recording(mabi, up=-9.81)
    findings = gravity_findings(recording.position, recording.current, mabi, gravity_of(mabi))
    assert kinds(findings) == dict.fromkeys(LOADED, 'nominal_sign')


@pytest.mark.parametrize(('scale', 'factor'), [(1e-3, '0.001 x'), (1e3, '1000 x')])
def test_a_label_a_thousand_times_off_is_named_as_a_unit_question(mabi, scale, factor) -> None:
    recording = nominal_recording(mabi)
    findings = gravity_findings(
        recording.position, recording.current * scale, mabi, gravity_of(mabi)
    )
    judged = [f for f in findings if f.joint in LOADED]
    assert kinds(judged) == dict.fromkeys(LOADED, 'nominal_scale')
    assert all(factor in f.text and "currents' unit" in f.text for f in judged)
    # The other joints have no gravity to judge by: a label 1000 x too small is still named
    # (``tiny_label_findings``), one 1000 x too large the plausibility gate refuses.
    tiny = {f.joint for f in findings if 'less than friction alone takes' in f.text}
    assert tiny == (set(mabi.joints) - set(LOADED) if scale < 1 else set())


def test_joints_the_gravity_torque_does_not_decide_are_not_judged(mabi) -> None:
    # joint_1 turns about the vertical: its gravity torque is 0 whatever the current.
    recording = nominal_recording(mabi)
    current = recording.current.copy()
    current[:, 0] *= -1000.0
    assert gravity_findings(recording.position, current, mabi, gravity_of(mabi)) == []


@settings(max_examples=40, deadline=None)
@given(
    gain=st.floats(1.5 / NOMINAL_SLOPE_FACTOR, NOMINAL_SLOPE_FACTOR / 1.5),
    offset=st.floats(-100.0, 100.0),
    seed=st.integers(0, 2**16),
)
def test_a_positive_gain_within_the_bounds_and_an_offset_pass_and_a_negative_one_is_a_sign(
    gain: float, offset: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    nominal = np.cumsum(rng.standard_normal((500, 3)), axis=0) * 10.0
    noise = 0.1 * rng.standard_normal(nominal.shape) * nominal.std(axis=0)
    label = gain * (nominal + noise) + offset
    limit = np.full(3, 10.0)
    joints = ('a', 'b', 'c')
    assert nominal_findings(label, nominal, joints, limit) == []
    flipped = nominal_findings(-label, nominal, joints, limit)
    assert kinds(flipped) == dict.fromkeys(joints, 'nominal_sign')


def test_check_content_warns_of_the_sign_on_load_and_inspect_lists_it(
    mabi, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    recording = nominal_recording(mabi)
    current = recording.current.copy()
    current[:, 2] *= -1
    flipped = replace(recording, current=current, source='flipped')
    with caplog.at_level(logging.WARNING):
        warnings = check_content(
            flipped.position,
            flipped.current,
            flipped.joints,
            where='flipped',
            nominal=(mabi, gravity_of(mabi)),
        )
    assert any('joint_3' in w and 'sign' in w for w in warnings)
    assert any('flipped: joint_3' in r.getMessage() for r in caplog.records)
    bag = write_recording(flipped, tmp_path / 'flipped')
    problems = inspect_bag(bag, robot=mabi, gravity=gravity_of(mabi)).problems
    assert [p for p in problems if 'gravity torque' in p] == [
        f'/motor_currents: {w}' for w in warnings
    ]
    assert (
        inspect_bag(
            write_recording(recording, tmp_path / 'clean'), robot=mabi, gravity=gravity_of(mabi)
        ).problems
        == ()
    )


def test_the_twins_default_bag_raises_no_finding(mabi) -> None:
    bag = REPO / 'bags/default'
    if not (bag / 'metadata.yaml').is_file():
        pytest.skip('bags/default is not built (make bags)')
    recording = load_recording(bag, mabi)
    assert gravity_findings(recording.position, recording.current, mabi, gravity_of(mabi)) == []


@pytest.mark.parametrize('name', ['mabi_max100', 'ur5', 'panda'])
def test_fresh_twin_recordings_of_each_robot_raise_no_finding(name: str) -> None:
    from id_learning.robot import load_robot_config
    from id_learning.twin import simulate

    robot = load_robot_config(REPO / 'config' / f'{name}.yaml')
    n = robot.n_joints
    measurement = {
        'current_noise_std_a': [0.01] * n,
        'current_resolution_a': 0.001,
        'encoder_counts_per_motor_turn': 1048576,
        'velocity_noise_std': 0.001,
        'joint_torque_noise_std': [0.1] * n,
    }
    config = twin_config(
        12.0, effects={}, robot=str(REPO / 'config' / f'{name}.yaml'), measurement=measurement
    )
    recording = simulate(config).recording
    assert gravity_findings(recording.position, recording.current, robot, gravity_of(robot)) == []
    assert sign_findings(recording.position, recording.current, robot.joints) == []
