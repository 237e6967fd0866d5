"""The diagnosed model kinds (rnea_effects, rnea_effects_mlp): fitted by diagnosing the training
part or taken from an effects.json, checked against pinocchio and the twin's hidden parameter."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import REPO, twin_config

from id_learning.dataset import prepare_dataset
from id_learning.diagnosis import diagnose, diagnose_training_part
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.artifact import ARTIFACT_HASH, document_digest
from id_learning.models.data import DiagnosedEffects, TrainingData
from id_learning.models.registry import load_model, make_model, save_model
from id_learning.physics import AugmentedModel
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.predictor import FeedForwardPredictor, GuardConfig, ReferenceSample
from id_learning.robot import load_robot_config
from id_learning.twin import simulate

VISCOUS_J1 = 35.0  # N*m*s/rad, hidden on joint 1 of an otherwise nominal twin


@pytest.fixture(scope='module')
def hidden_viscous():
    """A 200 s twin recording with only viscous friction on joint 1, as training data."""
    effects = {'viscous_friction': {'enabled': True, 'coefficient': [VISCOUS_J1] + [0] * 5}}
    config = twin_config(200.0, effects, seed=4)
    twin = simulate(config)
    robot = config.robot
    dataset = prepare_dataset(twin.recording, robot)
    # What the trainer does for the kinds built on the training part's diagnosis.
    diagnosed = DiagnosedEffects(*diagnose_training_part(dataset, robot))
    return robot, twin, TrainingData(dataset, robot, diagnosed=diagnosed)


@pytest.fixture(scope='module')
def fitted(hidden_viscous):
    """rnea_effects fitted by diagnosing the training part."""
    robot, _, data = hidden_viscous
    return make_model('rnea_effects', robot).fit(data)


def states(n_joints: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    return tuple(rng.uniform(-1.0, 1.0, (7, n_joints)) for _ in range(3))


def test_diagnosing_the_training_part_finds_the_hidden_friction(fitted):
    (spec, theta), *others = fitted.model_.terms
    assert (spec.name, spec.joint_name) == ('viscous_friction', 'joint_1')
    assert others == []
    assert theta[0] == pytest.approx(VISCOUS_J1, rel=0.1)
    assert 'training part' in fitted.fitted_metadata()['diagnosis']['source']


def test_prediction_is_pinocchio_rnea_plus_rotor_inertia_plus_the_effect(fitted, hidden_viscous):
    robot = hidden_viscous[0]
    q, v, a = states(robot.n_joints)
    drives = robot.drives
    expected = RigidBodyDynamics.from_config(robot).rnea(q, v, a)
    expected += drives.rotor_inertia * drives.gear_ratio**2 * a
    expected[:, 0] += fitted.model_.terms[0][1][0] * v[:, 0]
    np.testing.assert_allclose(fitted.predict(q, v, a), expected, rtol=1e-10, atol=1e-9)
    parts = fitted.components(q, v, a)
    np.testing.assert_allclose(parts.residual[:, 1:], 0.0, atol=1e-9)


def test_the_artifact_round_trips_and_is_checked(fitted, hidden_viscous, tmp_path):
    robot = hidden_viscous[0]
    folder = save_model(fitted, tmp_path / 'effects')
    again = load_model(folder, robot, 'rnea_effects')
    q, v, a = states(robot.n_joints, seed=1)
    np.testing.assert_array_equal(again.predict(q, v, a), fitted.predict(q, v, a))
    with pytest.raises(CheckpointError, match="not 'rnea_lq'"):
        load_model(folder, robot, 'rnea_lq')
    meta = json.loads((folder / 'model.json').read_text())
    meta['fitted']['terms'].append(meta['fitted']['terms'][0])
    meta[ARTIFACT_HASH] = document_digest(meta)  # consistent, as a faulty writer would leave it
    (folder / 'model.json').write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match='do not match 2 terms'):
        load_model(folder, robot)


@pytest.fixture(scope='module')
def effects_file(hidden_viscous, tmp_path_factory):
    """A diagnosis of the whole recording, written as a user's ``diagnose`` would."""
    robot, twin, _ = hidden_viscous
    out = tmp_path_factory.mktemp('diagnosis')
    return diagnose(twin.recording, robot, out_dir=out), out


def test_an_effects_file_is_taken_as_identified(effects_file, hidden_viscous):
    result, out = effects_file
    robot, _, data = hidden_viscous
    model = make_model('rnea_effects', robot, effects=str(out)).fit(data)
    q, v, a = states(robot.n_joints, seed=2)
    reference = AugmentedModel.from_dict(
        json.loads((out / 'effects.json').read_text())['model'], robot
    )
    np.testing.assert_array_equal(model.predict(q, v, a), reference.torque(q, v, a))
    np.testing.assert_allclose(model.predict(q, v, a), result.augmented_model.torque(q, v, a))


def test_the_mlp_on_top_learns_only_what_the_effects_leave(effects_file, hidden_viscous, tmp_path):
    _, out = effects_file
    robot, _, data = hidden_viscous
    model = make_model(
        'rnea_effects_mlp', robot, effects=str(out / 'effects.json'), max_epochs=2, device='cpu'
    ).fit(data)
    q, v, a = states(robot.n_joints, seed=3)
    physics = make_model('rnea_effects', robot, effects=str(out)).fit(data).predict(q, v, a)
    np.testing.assert_allclose(
        model.predict(q, v, a), physics + model.residual_torque(q, v), rtol=1e-12
    )
    again = load_model(save_model(model, tmp_path / 'mlp'), robot, 'rnea_effects_mlp')
    np.testing.assert_array_equal(again.predict(q, v, a), model.predict(q, v, a))


def test_unusable_effects_files_are_refused_by_name(effects_file, hidden_viscous, tmp_path):
    _, out = effects_file
    robot, _, data = hidden_viscous
    missing = tmp_path / 'nothing'
    with pytest.raises(ConfigError, match=r'nothing.* does not exist'):
        make_model('rnea_effects', robot, effects=str(missing)).fit(data)
    (tmp_path / 'bad.json').write_text('{"effects": []}')
    with pytest.raises(ConfigError, match=r'not an effects\.json'):
        make_model('rnea_effects', robot, effects=str(tmp_path / 'bad.json')).fit(data)
    saved = json.loads((out / 'effects.json').read_text())
    (tmp_path / 'joint.json').write_text(json.dumps({**saved, 'target': 'joint'}))
    with pytest.raises(ConfigError, match="'joint' torque"):
        make_model('rnea_effects', robot, effects=str(tmp_path / 'joint.json')).fit(data)
    ur5 = load_robot_config(REPO / 'config/ur5.yaml')
    other = TrainingData(data.dataset, ur5)
    with pytest.raises(ConfigError, match='does not fit'):
        make_model('rnea_effects', ur5, effects=str(out)).fit(other)


def test_the_feed_forward_predictor_serves_the_diagnosed_model(fitted, hidden_viscous, tmp_path):
    robot = hidden_viscous[0]
    folder = save_model(fitted, tmp_path / 'effects')
    # Random states, each its own history (a second apart) and no slew limit to speak of:
    # the model's torque itself is what is checked here.
    config = GuardConfig(period_s=robot.ipo_period_s, torque_rise_s=1e-4)
    predictor = FeedForwardPredictor.from_artifact(folder, robot, config)
    # it warns outside the (q, v, a) range of the training part, not of the joint limits
    assert predictor.range is not None
    assert predictor.range.source == 'training range (input_scaler)'
    q, v, a = states(robot.n_joints, seed=4)
    q *= 0.2  # inside the joint limits the predictor guards
    for k in range(len(q)):
        sample = ReferenceSample(10**9 * (k + 1), robot.joints, q[k], v[k], a[k])
        result = predictor.step(sample, receive_ns=10**9 * (k + 1))
        assert result.reject is None, result.detail
        expected = np.clip(
            fitted.predict(q[k], v[k], a[k])[0], *predictor.torque_limit * [[-1], [1]]
        )
        np.testing.assert_allclose(result.tau, expected, rtol=1e-12)


def test_one_sample_prediction_is_the_batch_prediction(effects_file, hidden_viscous):
    _, out = effects_file
    robot, _, data = hidden_viscous
    q, v, a = states(robot.n_joints, seed=5)
    for kind, extra in (('rnea_effects', {}), ('rnea_effects_mlp', {'max_epochs': 1})):
        model = make_model(kind, robot, effects=str(out), **extra).fit(data)
        one = model.sample_predictor()
        for k in range(len(q)):
            # float64 numpy against the batch path, whose MLP runs in float32
            expected = model.predict(q[k : k + 1], v[k : k + 1], a[k : k + 1])[0]
            np.testing.assert_allclose(
                one(q[k], v[k], a[k]), expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max()
            )
