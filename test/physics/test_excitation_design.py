"""The excitation designed for identification: its columns, its choice, its files, the twin.

References: pinocchio's RNEA (the base columns times the URDF's base parameters are the
rigid-body torque), the random design (one draw per segment is exactly it), the trajectory's own
coefficients (bag, CSV and the twin play them sample for sample).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from support import REPO

from id_learning.bag import read_joint_states
from id_learning.cli.main import main
from id_learning.errors import ConfigError
from id_learning.physics.excitation_design import (
    DESIGN_FILE,
    TRAJECTORY_CSV,
    IdentificationColumns,
    design_for_identification,
    load_design,
    write_design,
)
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.record.excitation import ExcitationConfig
from id_learning.robot import load_robot_config

SHORT = ExcitationConfig(duration_s=60.0)  # two 25 s segments


@pytest.fixture(scope='module')
def design(mabi):
    return design_for_identification(SHORT, mabi, np.random.default_rng(3), candidates=4)


def test_the_base_columns_carry_the_rigid_body_torque_and_are_independent(mabi):
    dynamics = RigidBodyDynamics.from_config(mabi)
    columns = IdentificationColumns(dynamics, mabi.limits)
    rng = np.random.default_rng(0)
    n, limits = mabi.n_joints, mabi.limits
    q = rng.uniform(limits.position_lower, limits.position_upper, (300, n))
    v = rng.uniform(-1, 1, (300, n)) * limits.velocity
    a = rng.uniform(-1, 1, (300, n)) * limits.acceleration
    y = columns(q, v, a)
    assert np.linalg.matrix_rank(y) == columns.count == y.shape[1]
    # The rigid-body torque lies in their span (a dropped column is one the others span).
    tau = dynamics.rnea(q, v, a).reshape(-1)
    fit = y @ np.linalg.lstsq(y, tau, rcond=None)[0]
    assert np.linalg.norm(fit - tau) <= 1e-8 * np.linalg.norm(tau)
    # ... and not in the span of the drive columns alone.
    drive = y[:, columns.keep >= columns.base.count]
    alone = drive @ np.linalg.lstsq(drive, tau, rcond=None)[0]
    assert np.linalg.norm(alone - tau) > 0.1 * np.linalg.norm(tau)


def test_one_draw_per_segment_is_the_random_design_and_more_draws_condition_better(mabi):
    random = design_for_identification(SHORT, mabi, np.random.default_rng(5), candidates=1)
    assert random.report.condition == pytest.approx(random.report.condition_random)
    assert random.report.coverage == pytest.approx(random.report.coverage_random)
    for seed in (5, 6):
        chosen = design_for_identification(SHORT, mabi, np.random.default_rng(seed), candidates=8)
        assert chosen.report.condition < chosen.report.condition_random


def test_the_design_rests_at_home_between_segments_within_the_limits(design, mabi):
    trajectory = design.trajectory
    slot = trajectory.period_s + trajectory.rest_s
    ends = np.array([k * slot + dt for k in range(len(trajectory.segments) + 1)
                     for dt in (0.0, trajectory.rest_s)])  # fmt: skip
    q_end, v_end, _ = trajectory.evaluate(ends)
    np.testing.assert_allclose(q_end, np.tile(trajectory.home, (len(ends), 1)), atol=1e-9)
    np.testing.assert_allclose(v_end, 0.0, atol=1e-9)
    q, v, a = trajectory.evaluate(np.arange(0.0, trajectory.duration_s, mabi.ipo_period_s / 4))
    limits = mabi.limits
    assert np.all(q >= limits.position_lower)
    assert np.all(q <= limits.position_upper)
    assert np.all(np.abs(v) <= limits.velocity)
    assert np.all(np.abs(a) <= limits.acceleration)


def test_the_files_replay_the_design_sample_for_sample(design, mabi, tmp_path):
    out = write_design(design, mabi, tmp_path / 'excite')
    states = read_joint_states(out, '/joint_states')
    t = (states.stamps_ns - states.stamps_ns[0]) * 1e-9
    q, v, a = design.trajectory.evaluate(t)
    np.testing.assert_allclose(states.position, q, atol=1e-12)
    np.testing.assert_allclose(states.velocity, v, atol=1e-12)
    table = np.loadtxt(out / TRAJECTORY_CSV, delimiter=',', skiprows=1)
    np.testing.assert_allclose(table[:, 1 + 2 * mabi.n_joints :], a, atol=1e-12)
    header = (out / TRAJECTORY_CSV).read_text().splitlines()[0].split(',')
    assert header[:2] == ['t_s', 'q_joint_1']
    assert header[-1] == 'qdd_joint_6'
    again = load_design(out / DESIGN_FILE, mabi, 'test')
    np.testing.assert_allclose(again.evaluate(t)[0], q, atol=0)


def test_a_design_for_other_joints_or_damaged_is_refused(design, mabi, tmp_path):
    out = write_design(design, mabi, tmp_path / 'excite')
    ur5 = load_robot_config(REPO / 'config' / 'ur5.yaml')
    with pytest.raises(
        ConfigError, match=r"excitation\.json: designed for joints .*'mabi_max100'"
    ):
        load_design(out / DESIGN_FILE, ur5, 'excitation.file')
    document = json.loads((out / DESIGN_FILE).read_text())
    del document['trajectory']['segments'][0]['a']
    (out / DESIGN_FILE).write_text(json.dumps(document))
    with pytest.raises(ConfigError, match=r"segments\[0\]: missing key\(s\) \['a'\]"):
        load_design(out / DESIGN_FILE, mabi, 'excitation.file')


def test_the_twin_plays_a_designed_file(design, mabi, tmp_path):
    from id_learning.twin import load_twin_config, simulate

    out = write_design(design, mabi, tmp_path / 'excite')
    config_text = (REPO / 'config' / 'twin_default.yaml').read_text()
    twin = tmp_path / 'twin.yaml'
    twin.write_text(
        config_text.replace('robot: mabi_max100.yaml', f'robot: {REPO}/config/mabi_max100.yaml')
    )
    designed = {'excitation': {'file': str(Path(out.name) / DESIGN_FILE)}, 'effects': {}}
    config = load_twin_config(twin, designed)
    recording = simulate(config).recording
    t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
    q = design.trajectory.evaluate(t)[0]
    assert recording.duration_s == pytest.approx(design.trajectory.duration_s, abs=0.01)
    np.testing.assert_allclose(recording.position, q, atol=1e-5)  # encoder quantisation


def test_the_command_writes_a_bag_and_says_its_figures(tmp_path, capsys):
    out = tmp_path / 'designed'
    argv = ['excitation', '--out', str(out), '--duration', '30', '--candidates', '2', '--quiet']
    assert main(argv) == 0
    said, warned = capsys.readouterr()
    assert '--duration 30 s became 26 s' in warned
    assert str((out / DESIGN_FILE).resolve()) in said  # a path that works from any config
    assert 'condition number is' in said
    assert 'a random design:' in said
    assert (out / 'metadata.yaml').is_file()
    assert (out / DESIGN_FILE).is_file()
    assert main(argv) == 2  # an existing bag is replaced only with --force
    assert main([*argv, '--force']) == 0
    twin = tmp_path / 'twin.yaml'
    robot = REPO / 'config' / 'mabi_max100.yaml'
    twin.write_text(f'robot: {robot}\nexcitation: {{file: designed/{DESIGN_FILE}}}\n')
    capsys.readouterr()
    simulate = ['simulate', '--config', str(twin), '--out', str(tmp_path / 'b')]
    assert main([*simulate, '--duration', '5']) == 2
    assert 'plays the designed excitation' in capsys.readouterr().err


def _edited(out: Path, edit) -> Path:
    document = json.loads((out / DESIGN_FILE).read_text())
    edit(document)
    (out / DESIGN_FILE).write_text(json.dumps(document))
    return out / DESIGN_FILE


@pytest.mark.parametrize(
    ('edit', 'match'),
    [
        (lambda d: d['trajectory']['segments'][0]['a'][0].__setitem__(0, float('nan')),
         r'segments\[0\]\.a: holds a value that is not a finite number'),
        (lambda d: d['trajectory'].__setitem__('rest_s', -1.0), r'rest_s -1 >= 0'),
        (lambda d: d['trajectory'].__setitem__('segments', []), 'no segment: nothing would move'),
        (lambda d: d.__setitem__('ipo_period_s', 0.004), r'IPO period of 0\.004 s'),
        (lambda d: d.__setitem__('extra', 1), r"unknown key\(s\) \['extra'\]"),
        (lambda d: d['trajectory']['segments'][0].pop('q0'), r"missing key\(s\) \['q0'\]"),
        (lambda d: d['trajectory']['segments'][0].__setitem__('b', [[0.0]] * 6),
         r'segments\[0\]\.b: shape \(6, 1\), expected \(6, 3\)'),
        (lambda d: d['trajectory'].__setitem__('omega_rad_s', 1.0), 'not 2 pi / period_s'),
    ],
)  # fmt: skip
def test_every_number_of_a_played_design_is_checked(design, mabi, tmp_path, edit, match):
    path = _edited(write_design(design, mabi, tmp_path / 'excite'), edit)
    with pytest.raises(ConfigError, match=match):
        load_design(path, mabi, 'excitation.file')


def test_a_design_named_for_another_robot_of_the_same_joints_is_said(
    design, mabi, tmp_path, caplog
):
    path = _edited(write_design(design, mabi, tmp_path / 'excite'),
                   lambda d: d.__setitem__('robot', 'mabi_copy'))  # fmt: skip
    load_design(path, mabi, 'excitation.file')
    assert "designed for 'mabi_copy', played on 'mabi_max100'" in caplog.text


def test_limits_name_the_joint_and_the_excess(design, mabi, tmp_path):
    def tripled(document):
        segment = document['trajectory']['segments'][0]
        segment['a'] = (3 * np.array(segment['a'])).tolist()

    fast = _edited(write_design(design, mabi, tmp_path / 'excite'), tripled)
    with pytest.raises(ConfigError, match=r'limit of joint_\d at t = .* \(by [0-9.e+-]+\)'):
        load_design(fast, mabi, 'excitation.file')


def test_settings_beside_a_designed_file_are_refused_naming_them(design, mabi, tmp_path):
    from id_learning.twin import load_twin_config

    write_design(design, mabi, tmp_path / 'excite')
    played = {'excitation': {'file': str(tmp_path / 'excite' / DESIGN_FILE), 'duration_s': 60}}
    with pytest.raises(ConfigError, match=r"so \['duration_s'\] would not apply"):
        load_twin_config(REPO / 'config' / 'twin_default.yaml', played)


@pytest.mark.parametrize(
    ('written', 'given_twice', 'key'),
    [
        ('"ipo_period_s": 0.008', '"ipo_period_s": 0.004, "ipo_period_s": 0.008', 'ipo_period_s'),
        ('"rest_s": ', '"rest_s": 2.0, "rest_s": ', 'rest_s'),
    ],
)
def test_a_design_that_gives_a_key_twice_is_refused_naming_file_and_key(
    design, mabi, tmp_path, written, given_twice, key
):
    """Probe 10's X01: json keeps the last of two equal keys without a word."""
    path = write_design(design, mabi, tmp_path / 'excite') / DESIGN_FILE
    text = path.read_text()
    assert text.count(written) == 1
    path.write_text(text.replace(written, given_twice))
    with pytest.raises(
        ConfigError, match=rf"^excitation\.file: {path}: the key '{key}' is given twice"
    ):
        load_design(path, mabi, 'excitation.file')


def test_a_design_file_that_is_a_device_is_refused_unread(mabi, tmp_path):
    path = tmp_path / DESIGN_FILE
    path.symlink_to('/dev/zero')
    with pytest.raises(ConfigError, match=rf'^excitation\.file: {path}: .*a character device'):
        load_design(path, mabi, 'excitation.file')
