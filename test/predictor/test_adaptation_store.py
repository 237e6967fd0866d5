"""The adaptation's stored state across sessions, and why it freezes (said once, by topic)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.predictor.adaptation_store import adaptation_path
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
    path.write_text('{"joints": ["a", "b"], "theta": []}', encoding='utf-8')
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
        '{"joints": ["a", "b"], "theta": []}'
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
