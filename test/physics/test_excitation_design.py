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
    with pytest.raises(ConfigError, match='its trajectory is damaged'):
        load_design(out / DESIGN_FILE, mabi, 'excitation.file')


def test_the_twin_plays_a_designed_file(design, mabi, tmp_path):
    from id_learning.twin import load_twin_config, simulate

    out = write_design(design, mabi, tmp_path / 'excite')
    config_text = (REPO / 'config' / 'twin_default.yaml').read_text()
    twin = tmp_path / 'twin.yaml'
    twin.write_text(
        config_text.replace('robot: mabi_max100.yaml', f'robot: {REPO}/config/mabi_max100.yaml')
        + '\n# designed\n'
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
    said = capsys.readouterr().out
    assert 'condition number is' in said
    assert 'a random design:' in said
    assert (out / 'metadata.yaml').is_file()
    assert (out / DESIGN_FILE).is_file()
    assert main(argv) == 2  # an existing bag is replaced only with --force
    assert main([*argv, '--force']) == 0
