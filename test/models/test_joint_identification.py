"""rnea_id_mlp's joint rounds: the physics identified again on the labels less the network.

Alternating minimisation of one objective: each round must keep the identification's guarantees
(physical bodies, the saved model loads), and is kept only where it lowers the whole model's
validation error (else the first fit is restored exactly).
"""

from __future__ import annotations

import numpy as np
import pytest
from support import quick_preprocess, twin_config

from id_learning.dataset.preprocess import prepare_dataset
from id_learning.errors import ConfigError
from id_learning.models.data import TrainingData
from id_learning.models.registry import load_model, make_model, save_model
from id_learning.twin import simulate

IDENTIFICATION = {'balancer': 'joint_2', 'iterations': 1, 'confirm': False}
QUICK = {'max_epochs': 6, 'device': 'cpu', 'stride': 8, 'seed': 3, 'width': 16}


@pytest.fixture(scope='module')
def data(mabi) -> TrainingData:
    result = simulate(twin_config(60.0, seed=11))
    return TrainingData(prepare_dataset(result.recording, mabi, quick_preprocess()), mabi)


@pytest.fixture(scope='module')
def sequential_and_joint(data):
    sequential = make_model('rnea_id_mlp', data.robot, **IDENTIFICATION, **QUICK).fit(data)
    joint = make_model('rnea_id_mlp', data.robot, **IDENTIFICATION, **QUICK, joint_rounds=2).fit(
        data
    )
    return sequential, joint


def test_a_round_is_kept_only_where_it_lowers_the_validation_error(data, sequential_and_joint):
    sequential, joint = sequential_and_joint
    before = sequential.identified_physics().arrays()
    after = joint.identified_physics().arrays()
    moved = any(not np.allclose(before[k], after[k]) for k in before)
    error = {m: m._validation_error(data) for m in (sequential, joint)}
    if moved:  # a kept round: lower on the validation tail
        assert error[joint] < error[sequential]
    else:  # none kept: the first fit, restored exactly
        assert error[joint] == error[sequential]


def test_the_joint_physics_stays_physical_and_the_model_round_trips(
    data, sequential_and_joint, tmp_path
):
    _, joint = sequential_and_joint
    save_model(joint, tmp_path / 'joint')  # the save checks physical consistency
    loaded = load_model(tmp_path / 'joint', data.robot)  # and so does the load
    ds = data.dataset
    np.testing.assert_allclose(
        loaded.predict(ds.q[:50], ds.v[:50], ds.a[:50]),
        joint.predict(ds.q[:50], ds.v[:50], ds.a[:50]),
        rtol=0,
        atol=1e-9,
    )
    assert loaded.config.joint_rounds == 2


@pytest.mark.parametrize('value', [-1, 21, 1.5, True])
def test_joint_rounds_outside_their_range_are_refused_naming_the_key(mabi, value):
    with pytest.raises(ConfigError, match='joint_rounds'):
        make_model('rnea_id_mlp', mabi, joint_rounds=value)
