"""benchmarks/real_robots.py: the real Panda's preparation on a small synthetic log, and the
published model's held-out RMSE against a hand computation. Needs nothing from ../shared."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pinocchio as pin
import pytest
import yaml
from support import REPO

JOINTS = [f'panda_joint{i}' for i in range(1, 8)]
EFFORT = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]
VELOCITY = [2.175] * 4 + [2.61] * 3
GRAVITY = 9.80665
FRICTION = {
    'friction_phi1': [0.5, 0.9, 0.6, 1.2, 0.8, 0.3, 0.5],
    'friction_phi2': [5.0, 9.0, 10.0, 5.5, 8.0, 17.0, 10.0],
    'friction_phi3': [0.04, 0.03, -0.05, 0.04, 0.03, -0.02, 0.004],
}


@pytest.fixture
def bench(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO / 'benchmarks'))
    return importlib.import_module('real_robots')


def chain_urdf() -> str:
    """A 7-joint serial arm with the Panda's joint names and limits (not the Panda)."""
    parts = ['<?xml version="1.0"?>', '<robot name="synthetic_panda">', '<link name="base"/>']
    parent = 'base'
    for i, name in enumerate(JOINTS):
        link = f'link{i + 1}'
        rpy = '0 0 0' if i % 2 == 0 else '-1.5707963 0 0'
        parts += [
            f'<link name="{link}"><inertial><origin xyz="0.03 0.01 0.08" rpy="0 0 0"/>'
            f'<mass value="{1.5 - 0.15 * i:.2f}"/><inertia ixx="0.01" ixy="0" ixz="0" '
            'iyy="0.012" iyz="0" izz="0.008"/></inertial></link>',
            f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{link}"/><origin xyz="0 0 0.15" rpy="{rpy}"/><axis xyz="0 0 1"/>'
            f'<limit lower="-2.8" upper="2.8" effort="{EFFORT[i]}" velocity="{VELOCITY[i]}"/>'
            '</joint>',
        ]
        parent = link
    parts += [
        '<link name="panda_link8"/>',
        f'<joint name="flange" type="fixed"><parent link="{parent}"/>'
        '<child link="panda_link8"/><origin xyz="0 0 0.1" rpy="0 0 0"/></joint>',
        '</robot>',
    ]
    return '\n'.join(parts)


def hand_friction(v):
    p1, p2, p3 = (np.asarray(FRICTION[f'friction_phi{k}']) for k in (1, 2, 3))
    return p1 / (1 + np.exp(-p2 * (v + p3))) - p1 / (1 + np.exp(-p2 * p3))


def hand_rnea(model, q, v, a):
    data = model.createData()
    return np.array([pin.rnea(model, data, *x).copy() for x in zip(q, v, a, strict=True)])


@pytest.fixture
def panda_dir(tmp_path):
    """A folder laid out like ../shared/data/panda_gaz2019, with a synthetic 10 s log whose
    torques are the published model's (RNEA + sigmoid friction) on a jittery ~1 kHz clock."""
    folder = tmp_path / 'panda_gaz2019'
    folder.mkdir()
    (folder / 'panda_gaz2019.urdf').write_text(chain_urdf())
    (folder / 'panda_gaz2019_params.json').write_text(json.dumps({'gravity': GRAVITY, **FRICTION}))
    rng = np.random.default_rng(5)
    t = np.concatenate([[0.0], np.cumsum(0.001 + rng.uniform(-0.0003, 0.0003, 9999))])
    t[5000:] += 0.006  # a pause well inside max_gap_s
    freq = 0.25 + 0.05 * np.arange(7)
    w = 2 * np.pi * freq
    q = 0.6 * np.sin(w * t[:, None]) - 0.2
    qd = 0.6 * w * np.cos(w * t[:, None])
    qdd = -0.6 * w**2 * np.sin(w * t[:, None])
    model = pin.buildModelFromUrdf(str(folder / 'panda_gaz2019.urdf'))
    model.gravity.linear = np.array([0.0, 0.0, -GRAVITY])
    tau = hand_rnea(model, q, qd, qdd) + hand_friction(qd)
    np.savez(folder / 'panda_exciting_traj1.npz', t=t, q=q, qd=qd, tau=tau)
    return folder


def test_config_and_mapping_import_and_the_published_rmse_is_the_hand_one(
    bench, panda_dir, tmp_path
):
    from id_learning.robot import load_robot_config

    out = tmp_path / 'work'
    job = bench.prepare_panda_real(panda_dir, out)
    assert job.steps['import']['returncode'] == 0, job.steps['import'].get('error')
    assert job.steps['import']['cpu_s'] > 0
    # Nothing copied: the config names the log's URDF where it is.
    robot = load_robot_config(job.robot_yaml)
    assert robot.urdf_path == (panda_dir / 'panda_gaz2019.urdf').resolve()
    assert robot.limits.torque.tolist() == EFFORT
    assert robot.limits.velocity.tolist() == VELOCITY
    assert robot.ipo_period_s == bench.PANDA_PERIOD_S
    mapping = yaml.safe_load((out / 'import_mapping.yaml').read_text())
    assert mapping['resample']['method'] == 'interpolate'
    assert job.target == 'joint'

    config = bench.preprocess_of(out / 'no_run', 'joint')
    dataset = bench.load_dataset(job.bags, robot, config)
    n = len(dataset.tau)
    with np.load(panda_dir / 'panda_exciting_traj1.npz') as log:
        span = log['t'][-1] - log['t'][0]
    assert abs(n - (span / bench.PANDA_PERIOD_S + 1)) <= 1  # the 1 ms grid, one segment
    rows = dataset.test_rows
    # The test part: the last 30 % in time, contiguous.
    assert rows[-1] == n - 1
    assert np.all(np.diff(rows) == 1)
    assert abs(len(rows) - 0.3 * n) <= 1

    published = bench.heldout_rmse(job.published, dataset)
    # By hand: pinocchio's RNEA with the paper's gravity plus the friction formula on the
    # controller's inputs, low-passed like the labels, RMSE on the test rows.
    model = pin.buildModelFromUrdf(str(panda_dir / 'panda_gaz2019.urdf'))
    model.gravity.linear = np.array([0.0, 0.0, -GRAVITY])
    motion = dataset.controller
    torque = hand_rnea(model, motion.q, motion.v, motion.a) + hand_friction(motion.v)
    filtered = dataset.filter_like_labels(torque)[rows]
    by_hand = np.sqrt(np.mean((filtered - dataset.tau[rows]) ** 2, axis=0))
    np.testing.assert_allclose(published, by_hand, rtol=1e-9, atol=1e-12)

    # The log's torques are the published model's: it fits them far better than a model
    # without its friction, or with the friction's sign flipped.
    label_rms = np.sqrt(np.mean(dataset.tau[rows] ** 2, axis=0))
    assert np.all(np.asarray(published) < 0.05 * label_rms)
    friction_rms = np.sqrt(np.mean(hand_friction(motion.v[rows]) ** 2, axis=0))
    no_friction = bench.heldout_rmse(bench.PublishedModel(robot, None, gravity=GRAVITY), dataset)
    assert np.all(np.asarray(published) < 0.3 * np.asarray(no_friction))
    np.testing.assert_allclose(no_friction, friction_rms, rtol=0.3)


def test_friction_law_and_table(bench):
    v = np.array([[0.0] * 7, [0.5] * 7, [-0.5] * 7])
    p = {k: np.asarray(FRICTION[f'friction_{k}']) for k in ('phi1', 'phi2', 'phi3')}
    f = bench.sigmoid_friction(v, p['phi1'], p['phi2'], p['phi3'])
    np.testing.assert_allclose(f[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(f, hand_friction(v))
    assert np.all(f[1] > 0)
    assert np.all(f[2] < 0)
    with pytest.raises(ValueError, match='phi2'):
        bench.check_friction({'model': 'sigmoid', 'phi1': [1.0] * 7, 'phi2': [1.0], 'phi3': 0}, 7)
    entry = {'joints': ['a', 'b'], 'rmse_nm': {'mlp': [1.0, 3.0], 'published': [0.5, 0.25]}}
    table = bench.rmse_table(entry)
    assert table[0] == '| model | j1 | j2 | mean |'
    assert table[2:] == ['| mlp | 1 | 3 | 2 |', '| published | 0.5 | 0.25 | 0.375 |']
