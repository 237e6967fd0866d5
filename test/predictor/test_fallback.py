"""Outside the training range a network falls back to the physics prior, blended across the
margin; checked against pinocchio's RNEA of the URDF and the artifacts' own predictions."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from predictor.tiny_artifacts import reference_run
from support import REPO

from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.registry import load_model
from id_learning.predictor import FeedForwardPredictor, GuardConfig, ReferenceSample
from id_learning.predictor.fallback import blend_weight


def nominal_motor_torque(robot, q, v, a) -> np.ndarray:
    """RNEA of the URDF plus the datasheet rotor inertia, built here from pinocchio."""
    model = pin.buildModelFromUrdf(str(REPO / 'urdf/mabi_max100.urdf'))
    rigid = pin.rnea(model, model.createData(), q, v, a)
    return rigid + robot.drives.rotor_inertia * robot.drives.gear_ratio**2 * a


def joint_torque_rnea_lq(folder, robot):
    """An rnea_lq artifact fitted on joint torques (the tiny ones are fitted on motor torques)."""
    from dataclasses import replace

    from predictor.tiny_artifacts import training_recording
    from support import quick_preprocess

    from id_learning.dataset import prepare_dataset
    from id_learning.models.data import TrainingData
    from id_learning.models.registry import make_model, save_model

    recording = training_recording()
    recording = replace(recording, joint_torque=100.0 * recording.current)
    dataset = prepare_dataset(recording, robot, quick_preprocess(target='joint'))
    model = make_model('rnea_lq', robot).fit(TrainingData(dataset, robot))
    return save_model(model, folder / 'rnea_lq_joint', {'preprocessing': {'target': 'joint'}})


def sample_at(k: int, q, v, a, joints) -> ReferenceSample:
    """Sample k of a stream whose samples lie a second apart: each starts a history of its own
    (the states below jump in ways no motion does, which the consistency gate would hold)."""
    return ReferenceSample(1_000_000_000 * (1 + k), tuple(joints), q, v, a)


def outside(predictor, q, times: float) -> np.ndarray:
    """q with joint_1 moved ``times`` half ranges beyond the top of its training range."""
    low, high = predictor._training_range.bounds['q']
    q = q.copy()
    q[0] = high[0] + times * 0.5 * (high[0] - low[0])
    return q


def test_blend_weight_is_zero_inside_one_beyond_the_margin_and_smooth_between():
    assert blend_weight(0.0, 0.1) == 0.0
    assert blend_weight(-1.0, 0.1) == 0.0
    assert blend_weight(0.1, 0.1) == 1.0
    assert blend_weight(5.0, 0.1) == 1.0
    assert blend_weight(0.05, 0.1) == pytest.approx(0.5)
    x = np.linspace(0.0, 0.1, 101)
    w = np.array([blend_weight(e, 0.1) for e in x])
    assert np.all(np.diff(w) >= 0)
    assert np.max(np.abs(np.diff(w))) < 0.02  # no step: at most 1.5x the mean slope per step
    assert blend_weight(1e-9, 0.0) == 1.0  # no margin: a switch at the range's edge


def test_a_network_falls_back_to_the_nominal_model_beyond_its_range_and_back(tiny_artifacts, mabi):
    predictor = FeedForwardPredictor.from_artifact(tiny_artifacts['mlp'], mabi)
    assert predictor.out_of_range_action == 'fallback'  # 'auto' on a network
    assert 'nominal model' in predictor.fallback.source
    model = load_model(tiny_artifacts['mlp'], mabi)
    _, q, v, a = reference_run(3)
    inside = predictor.step(sample_at(0, q[0], v[0], a[0], mabi.joints), 0)
    assert inside.physics_share == 0.0
    np.testing.assert_allclose(inside.tau, model.predict(q[:1], v[:1], a[:1])[0], rtol=1e-5)

    far = outside(predictor, q[1], 3.0)
    result = predictor.step(sample_at(1, far, v[1], a[1], mabi.joints), 1_000_000_000)
    assert result.physics_share == 1.0
    assert result.is_out_of_range
    assert 'q of joint_1' in result.detail
    assert 'nominal model' in result.detail
    expected = nominal_motor_torque(mabi, far, v[1], a[1])
    np.testing.assert_allclose(result.tau, expected, rtol=1e-9, atol=1e-9)
    assert predictor.counters.fallback_samples == 1
    assert predictor.counters.out_of_range == 1

    back = predictor.step(sample_at(2, q[2], v[2], a[2], mabi.joints), 2_000_000_000)
    assert back.physics_share == 0.0
    np.testing.assert_allclose(back.tau, model.predict(q[2:], v[2:], a[2:])[0], rtol=1e-5)


def test_in_the_margin_the_torque_is_the_smooth_blend_of_network_and_physics(tiny_artifacts, mabi):
    margin = 0.2
    predictor = FeedForwardPredictor.from_artifact(
        tiny_artifacts['delan'], mabi, GuardConfig(range_margin=margin)
    )
    model = load_model(tiny_artifacts['delan'], mabi)
    _, q, v, a = reference_run(3)
    near = outside(predictor, q[0], 0.25 * margin)
    result = predictor.step(sample_at(0, near, v[0], a[0], mabi.joints), 0)
    share = 0.25**2 * (3 - 2 * 0.25)
    assert result.physics_share == pytest.approx(share)
    assert not result.is_out_of_range  # inside the widened range: not counted as out of it
    network = model.predict(near[None], v[:1], a[:1])[0]
    physics = nominal_motor_torque(mabi, near, v[0], a[0])
    np.testing.assert_allclose(result.tau, (1 - share) * network + share * physics, rtol=1e-5)
    assert predictor.counters.fallback_samples == 1
    assert predictor.counters.out_of_range == 0


def test_the_identified_model_beside_the_network_in_its_run_is_the_prior(tmp_path, mabi):
    from predictor.tiny_artifacts import build_tiny_artifacts

    folders = build_tiny_artifacts(tmp_path / 'models', mabi, kinds=['mlp', 'rnea_id'])
    predictor = FeedForwardPredictor.from_artifact(folders['mlp'], mabi)
    assert predictor.fallback.source.startswith('rnea_id artifact')
    identified = load_model(folders['rnea_id'], mabi)
    _, q, v, a = reference_run(3)
    far = outside(predictor, q[0], 3.0)
    result = predictor.step(sample_at(0, far, v[0], a[0], mabi.joints), 0)
    # The prior serves the torque the drive needs: the labels' identified delay left out.
    expected = identified.for_the_drive().predict(far[None], v[:1], a[:1])[0]
    np.testing.assert_allclose(result.tau, np.clip(expected, -mabi.limits.torque,
                                                   mabi.limits.torque), rtol=1e-9)  # fmt: skip


def test_a_physics_model_warns_and_a_bad_fallback_artifact_is_refused(
    tmp_path, tiny_artifacts, mabi
):
    physics = FeedForwardPredictor.from_artifact(tiny_artifacts['rnea_lq'], mabi)
    assert physics.out_of_range_action == 'warn'
    assert physics.fallback is None
    # A physics model is its own prior: asked to fall back, it warns (also when changed live).
    asked = GuardConfig(out_of_range='fallback')
    assert (
        FeedForwardPredictor.from_artifact(
            tiny_artifacts['rnea_lq'], mabi, asked
        ).out_of_range_action
        == 'warn'
    )
    physics.update_config(asked)
    assert physics.out_of_range_action == 'warn'
    network = load_model(tiny_artifacts['mlp'], mabi)
    with pytest.raises(ConfigError, match="'fallback' needs a physics prior"):
        FeedForwardPredictor(network, mabi.limits.torque, asked)
    with pytest.raises(CheckpointError, match='is a network, not a physics prior'):
        FeedForwardPredictor.from_artifact(
            tiny_artifacts['mlp'], mabi, fallback_artifact=tiny_artifacts['lnn']
        )
    explicit = FeedForwardPredictor.from_artifact(
        tiny_artifacts['mlp'], mabi, fallback_artifact=tiny_artifacts['rnea_lq']
    )
    assert explicit.fallback.source.startswith('rnea_lq artifact')
    with pytest.raises(
        CheckpointError, match='fitted on joint torques, the served model on motor'
    ):
        FeedForwardPredictor.from_artifact(
            tiny_artifacts['mlp'], mabi, fallback_artifact=joint_torque_rnea_lq(tmp_path, mabi)
        )
    with pytest.raises(CheckpointError, match='not a model artifact'):
        FeedForwardPredictor.from_artifact(
            tiny_artifacts['mlp'], mabi, fallback_artifact=tmp_path / 'nothing'
        )
