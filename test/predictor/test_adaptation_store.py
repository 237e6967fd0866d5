"""The adaptation's stored state across sessions, and why it freezes (said once, by topic)."""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.predictor.adaptation_store import MAX_STATE_BYTES, adaptation_path
from id_learning.robot.config import RobotConfig

TOPIC = '/motor_currents'
#: One kind of currents message: what a session receives.
KINDS = ('valid', 'nan', 'renamed', 'short')


def new_loop(robot: RobotConfig, *, inertia: bool = False) -> AdaptationLoop:
    return AdaptationLoop.for_robot(robot, robot.joints, AdaptationConfig(), inertia=inertia)


def session(loop: AdaptationLoop, robot: RobotConfig, kinds: list[str], seed: int = 0) -> None:
    """Serve a sample per kind and answer it with currents of that kind."""
    rng = np.random.default_rng(seed)
    joints, n = list(robot.joints), len(robot.joints)
    for k, kind in enumerate(kinds):
        stamp = 1_000_000 + k * 8_000_000
        q, v = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
        loop.serve(stamp, (q, v, np.zeros(n)), np.zeros(n))
        effort = list(rng.normal(0.0, 0.5, n))  # small currents: within the gate
        names = list(joints)
        if kind == 'nan':
            effort[2] = math.nan
        elif kind == 'renamed':
            names = [f'axis_{j + 1}' for j in range(n)]
        elif kind == 'short':
            effort = effort[:-1]
        loop.measured_message(stamp, names, effort, joints, TOPIC)


@pytest.fixture
def artifact(tmp_path: Path) -> Path:
    path = tmp_path / 'models' / 'rnea_lq'
    path.mkdir(parents=True)
    return path


def test_a_session_that_learnt_nothing_leaves_the_stored_state_as_it_was(
    mabi: RobotConfig, artifact: Path
) -> None:
    first = new_loop(mabi)
    first.load(artifact, mabi.joints)
    session(first, mabi, ['valid'] * 200)
    assert first.save(artifact, mabi.joints) is not None
    stored = adaptation_path(artifact).read_bytes()
    assert np.abs(json.loads(stored)['theta']).sum() > 0

    second = new_loop(mabi)
    second.load(artifact, mabi.joints)
    session(second, mabi, ['nan'] * 50)
    is_warning, line = second.finish(artifact, mabi.joints)

    assert adaptation_path(artifact).read_bytes() == stored
    assert not is_warning
    assert 'accepted no update' in line
    assert 'left as it was' in line


def test_a_session_continues_from_what_was_stored_and_adds_its_updates(
    mabi: RobotConfig, artifact: Path
) -> None:
    first = new_loop(mabi)
    first.load(artifact, mabi.joints)
    session(first, mabi, ['valid'] * 100)
    first.save(artifact, mabi.joints)
    v = np.full(len(mabi.joints), 0.3)

    second = new_loop(mabi)
    base = second.load(artifact, mabi.joints)

    assert base.problem is None
    assert base.updates_before == 100
    np.testing.assert_array_equal(second.adapter.correction(v), first.adapter.correction(v))
    session(second, mabi, ['valid'] * 20, seed=1)
    saved = second.save(artifact, mabi.joints)
    assert saved is not None
    assert '20 updates of this session on top of 100' in saved[1]
    state = json.loads(adaptation_path(artifact).read_text())
    assert (state['updates'], state['updates_total']) == (20, 120)
    assert sorted(p.name for p in artifact.parent.iterdir()) == [
        artifact.name,
        adaptation_path(artifact).name,
    ]  # no temporary file left


def test_the_rigid_body_mode_continues_from_its_own_state(
    mabi: RobotConfig, artifact: Path
) -> None:
    first = new_loop(mabi, inertia=True)
    first.load(artifact, mabi.joints)
    session(first, mabi, ['valid'] * 100)
    assert first.save(artifact, mabi.joints) is not None
    assert first.inertia is not None

    second = new_loop(mabi, inertia=True)
    assert second.load(artifact, mabi.joints).problem is None
    assert second.inertia is not None
    np.testing.assert_array_equal(second.inertia.estimate, first.inertia.estimate)

    friction_only = new_loop(mabi)
    assert 'mode' in (friction_only.load(artifact, mabi.joints).problem or '')


def test_a_file_it_cannot_continue_from_is_kept_aside_not_overwritten(
    mabi: RobotConfig, artifact: Path
) -> None:
    path = adaptation_path(artifact)
    # For this model (a folder without model.json: no artifact_sha256), of other joints.
    path.write_text('{"artifact_sha256": null, "joints": ["a", "b"]}', encoding='utf-8')
    loop = new_loop(mabi)
    base = loop.load(artifact, mabi.joints)
    assert base.problem is not None
    line = base.line()
    assert line is not None
    assert line[0]
    assert 'starts from zero' in line[1]

    session(loop, mabi, ['valid'] * 10)
    loop.save(artifact, mabi.joints)

    assert (path.parent / f'{path.name}.previous').read_text() == (
        '{"artifact_sha256": null, "joints": ["a", "b"]}'
    )
    assert json.loads(path.read_text())['updates'] == 10


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(kinds=st.lists(st.sampled_from(KINDS), max_size=30), stored=st.booleans())
def test_the_stored_state_changes_exactly_when_the_session_accepted_an_update(
    mabi: RobotConfig, tmp_path: Path, kinds: list[str], stored: bool
) -> None:
    artifact = tmp_path / 'rnea_lq'
    artifact.mkdir(exist_ok=True)  # the model's folder: the state is written beside it
    path = adaptation_path(artifact)
    path.unlink(missing_ok=True)
    if stored:
        earlier = new_loop(mabi)
        earlier.load(artifact, mabi.joints)  # no file yet: a fresh start
        session(earlier, mabi, ['valid'] * 5, seed=9)
        earlier.save(artifact, mabi.joints)
    before = path.read_bytes() if path.exists() else None
    loop = new_loop(mabi)
    loop.load(artifact, mabi.joints)

    session(loop, mabi, kinds)
    loop.finish(artifact, mabi.joints)

    after = path.read_bytes() if path.exists() else None
    learnt = loop.session_updates > 0
    assert learnt == ('valid' in kinds)
    assert (after != before) == learnt
    assert loop.adapter.counters.frozen == sum(kind != 'valid' for kind in kinds)


def test_each_kind_of_freeze_reason_is_said_once_naming_the_topic_and_what_is_wrong(
    mabi: RobotConfig,
) -> None:
    loop = new_loop(mabi)
    session(loop, mabi, ['nan', 'nan', 'renamed', 'short', 'renamed'])

    lines = loop.take_reasons()

    assert len(lines) == 3
    assert all(is_warning and TOPIC in line for is_warning, line in lines)
    nan, renamed, short = (line for _, line in lines)
    assert f"['{mabi.joints[2]}'] not finite" in nan
    assert "missing ['joint_1'" in renamed
    assert "unexpected ['axis_1'" in renamed
    assert f'{len(mabi.joints) - 1} values for {len(mabi.joints)} names' in short
    assert loop.take_reasons() == []  # said once
    session(loop, mabi, ['nan'])
    assert loop.take_reasons() == []
    report = loop.report(mabi.joints)
    assert report['adaptation_frozen'] == 6
    assert 'not finite' in str(report['adaptation_frozen_reason'])


# -- a stored state is checked against what the adaptation keeps online ---------------------------
def _stream(loop: AdaptationLoop, robot: RobotConfig, levels: list[float], seed: int) -> None:
    """Serve a sample per level; answer it with currents of that many times the torque limits."""
    rng = np.random.default_rng(seed)
    joints, n = list(robot.joints), len(robot.joints)
    amperes = robot.limits.torque / loop.torque_per_ampere
    for k, level in enumerate(levels):
        stamp = 1_000_000 + k * 8_000_000
        loop.serve(stamp, (rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(n)), np.zeros(n))
        loop.measured_message(stamp, joints, list(level * amperes), joints, TOPIC)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    levels=st.lists(
        st.one_of(st.floats(-1e6, 1e6), st.sampled_from([0.0, 5.0, -5.0, 1e6])), min_size=1,
        max_size=60,
    ),
    inertia=st.booleans(),
    memory=st.sampled_from([0.08, 60.0]),
)  # fmt: skip
def test_what_a_session_stores_the_next_continues_from_whatever_it_was_fed(
    mabi: RobotConfig, tmp_path: Path, levels: list[float], inertia: bool, memory: float
) -> None:
    """The limits kept online keep every stored value loadable, whatever the currents.

    Absurd ones too (a million times the torque limit), with a memory of ten cycles that takes
    them in at once (the error scale and the estimate reach their limits).
    """
    artifact = tmp_path / 'rnea_lq'
    artifact.mkdir(exist_ok=True)  # the model's folder: the state is written beside it
    path = adaptation_path(artifact)
    path.unlink(missing_ok=True)
    config = AdaptationConfig(time_constant_s=memory)
    first = AdaptationLoop.for_robot(mabi, mabi.joints, config, inertia=inertia)
    first.load(artifact, mabi.joints)
    _stream(first, mabi, levels, seed=len(levels))
    first.save(artifact, mabi.joints)
    second = new_loop(mabi, inertia=inertia)
    assert second.load(artifact, mabi.joints).problem is None


def _corrupt(artifact: Path, robot: RobotConfig, key: str, joint: int, column: int, value: float,
             *, inertia: bool = False) -> str:  # fmt: skip
    """Store a session's state with one value replaced; the file's text."""
    loop = new_loop(robot, inertia=inertia)
    loop.load(artifact, robot.joints)
    session(loop, robot, ['valid'] * 20)
    loop.save(artifact, robot.joints)
    path = adaptation_path(artifact)
    state = json.loads(path.read_text())
    if key in ('error_scale_nm', 'change'):
        state[key][joint] = value
    else:
        state[key][joint][column] = value
    path.write_text(json.dumps(state))
    return path.read_text()


@pytest.mark.parametrize(
    ('key', 'column', 'value', 'message'),
    [
        ('theta', 0, 1e12, r"'theta' of joint_2 coulomb_level_nm is 1e\+12, beyond the 1500 "
                           'the applied correction is bounded to'),
        ('estimate', 2, -1e12, r"'estimate' of joint_2 offset_nm is -1e\+12, beyond the 15000 "),
        ('error_scale_nm', 0, 0.0, r"'error_scale_nm' of joint_2 is 0, not above 0"),
        ('error_scale_nm', 0, 1e12, r"'error_scale_nm' of joint_2 is 1e\+12, beyond the 15000"),
    ],
)  # fmt: skip
def test_a_stored_value_beyond_the_adaptations_limits_is_refused_naming_file_joint_and_value(
    mabi: RobotConfig, artifact: Path, key: str, column: int, value: float, message: str
) -> None:
    """The probe's file: theta and estimate 1e12 gave each joint its bounded correction."""
    text = _corrupt(artifact, mabi, key, 1, column, value)
    loop = new_loop(mabi)
    base = loop.load(artifact, mabi.joints)
    assert base.problem is not None
    assert re.search(message, base.problem), base.problem
    line = base.line()
    assert line is not None
    assert line[0]
    assert str(adaptation_path(artifact)) in line[1]
    assert not loop.adapter.theta.any()  # starts from zero
    assert adaptation_path(artifact).read_text() == text  # untouched at start
    session(loop, mabi, ['valid'] * 5)
    loop.save(artifact, mabi.joints)
    aside = adaptation_path(artifact).with_name(f'{adaptation_path(artifact).name}.previous')
    assert aside.read_text() == text  # kept aside, not overwritten


def test_a_stored_base_parameter_change_beyond_its_limit_is_refused_by_name(
    mabi: RobotConfig, artifact: Path
) -> None:
    _corrupt(artifact, mabi, 'change', 0, 0, 1e15, inertia=True)
    loop = new_loop(mabi, inertia=True)
    problem = loop.load(artifact, mabi.joints).problem or ''
    assert re.search(r"'change' of base parameter .+ is 1e\+15, beyond the ", problem), problem


@pytest.mark.parametrize('kind', ['fifo', 'large'])
def test_a_state_file_that_is_no_file_or_too_large_is_named_not_waited_on(
    mabi: RobotConfig, artifact: Path, kind: str
) -> None:
    """A FIFO nobody writes, or a file past the cap: a problem said at once, a start from zero."""
    path = adaptation_path(artifact)
    if kind == 'fifo':
        os.mkfifo(path)
    else:
        with path.open('wb') as stream:
            stream.truncate(MAX_STATE_BYTES + 1)
    base = new_loop(mabi).load(artifact, mabi.joints)
    expected = 'a FIFO (named pipe), not a regular file' if kind == 'fifo' else 'larger than 1 MiB'
    assert expected in (base.problem or '')
    assert str(path) in (base.problem or '')
