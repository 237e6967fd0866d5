"""The diagnosis on twin recordings whose hidden effects it is not told (a fast subset of the
scoring in benchmarks/diagnosis_scoring.py), its report, and its failure paths."""

from __future__ import annotations

import json
import re
from dataclasses import replace

import numpy as np
import pytest
from support import twin_config

from id_learning.diagnosis import (
    DiagnosisConfig,
    augmented_torque,
    diagnose,
    filtered_prediction,
    run_diagnosis,
)
from id_learning.diagnosis.report import render_summary
from id_learning.errors import ConfigError, DatasetError, RobotModelError
from id_learning.physics import AugmentedModel, EffectSpec
from id_learning.twin import simulate

DURATION_S = 150.0  # five excitation segments: enough independent samples in the held-out part
SEED = 11


def hidden(effects: dict) -> tuple:
    config = twin_config(DURATION_S, effects, seed=SEED)
    return config, simulate(config)


def named(result) -> set[tuple[str, str | None]]:
    return {(e.name, e.spec.joint_name or None) for e in result.named_effects()}


@pytest.fixture(scope='module')
def viscous_joint_1(tmp_path_factory):
    """Viscous friction hidden on joint 1, diagnosed with the report written."""
    config, twin = hidden({'viscous_friction': {'enabled': True, 'coefficient': [35.0] + [0] * 5}})
    out = tmp_path_factory.mktemp('diagnosis')
    return config, twin, diagnose(twin.recording, config.robot, out_dir=out), out


def test_nothing_hidden_names_nothing():
    config, twin = hidden({})
    result = run_diagnosis(twin.recording, config.robot)
    assert result.effects == []
    assert result.structured_joints() == []
    ratios = [r.ratio for r in result.remainder]
    assert max(ratios) < 1.25  # the residual is the label noise, at its estimated level


def test_viscous_friction_on_joint_1_is_named_with_its_coefficient(viscous_joint_1):
    _, _, result, _ = viscous_joint_1
    truth = 35.0
    assert named(result) == {('viscous_friction', 'joint_1')}
    (effect,) = result.named_effects()
    assert effect.coefficients[0] == pytest.approx(truth, rel=0.1)
    low, high = effect.parameters[0]['ci']
    assert low < effect.coefficients[0] < high
    assert result.rmse_after_nm[0] < 0.6 * result.rmse_before_nm[0]


def test_augmented_torque_is_the_nominal_model_plus_the_found_effect(viscous_joint_1):
    _, twin, result, _ = viscous_joint_1
    rng = np.random.default_rng(0)
    q = rng.uniform(-0.5, 0.5, (5, 6))
    v = rng.uniform(-1.0, 1.0, (5, 6))
    a = rng.uniform(-1.0, 1.0, (5, 6))
    nominal = result.nominal_model.evaluate(q, v, a).tau_nominal
    expected = nominal.copy()
    expected[:, 0] += result.effects[0].coefficients[0] * v[:, 0]
    np.testing.assert_allclose(augmented_torque(result, q, v, a), expected, rtol=1e-12)
    # what a model artifact stores: effects.json's model rebuilds the same torque
    saved = json.loads(result.to_json())['model']
    again = AugmentedModel.from_dict(saved, result.robot)
    np.testing.assert_allclose(again.torque(q, v, a), expected, rtol=0, atol=0)
    with pytest.raises(RobotModelError, match='identified for joints'):
        AugmentedModel.from_dict({**saved, 'joints': ['a', 'b']}, result.robot)
    dataset, model = filtered_prediction(result, twin.recording)
    assert model.shape == dataset.tau.shape


def test_report_and_effects_json_hold_what_the_issue_asks_for(viscous_joint_1):
    _, _, result, tmp_path = viscous_joint_1
    report = (tmp_path / 'report.md').read_text(encoding='utf-8')
    assert 'viscous_friction' in report
    for figure in ('waterfall.png', 'residual_location.png', 'residual_time.png'):
        assert (tmp_path / figure).stat().st_size > 1000
        assert f'({figure})' in report
    data = json.loads((tmp_path / 'effects.json').read_text(encoding='utf-8'))
    for key in (
        'effects',
        'alias_sets',
        'untestable',
        'unexplained_remainder',
        'held_out_rmse_nm',
    ):
        assert key in data
    (effect,) = data['effects']
    assert effect['name'] == 'viscous_friction'
    assert effect['joint'] == 'joint_1'
    assert effect['parameters'][0]['ci'][0] < effect['parameters'][0]['value']
    # Its datasheet tolerances are named where the parameters were estimated with them.
    (scale,) = [m for m in data['marginalised'] if m.startswith('torque_constant_scale[joint_1')]
    section = report.split('## Effects in the refit model')[1].split('\n## ')[0]
    assert scale in section
    assert data['stand_ins'] == []
    assert len(data['held_out_rmse_nm']['before']) == 6
    assert data['held_out_rmse_nm']['waterfall'][0]['added'] == result.effects[0].label


def test_a_torque_offset_is_named_from_two_recordings_together():
    effects = {'torque_offset': {'enabled': True, 'offset': [0.0, 0.0, 0.0, 3.0, 0.0, 0.0]}}
    configs = [twin_config(80.0, effects, seed=seed) for seed in (21, 22)]
    recordings = [simulate(config).recording for config in configs]
    with pytest.raises(DatasetError, match='too short'):
        run_diagnosis(recordings[0], configs[0].robot)  # one alone holds too little
    result = run_diagnosis(recordings, configs[0].robot)
    assert len(result.sources) == 2
    assert named(result) == {('torque_offset', 'joint_4')}
    assert result.effects[0].coefficients[0] == pytest.approx(3.0, rel=0.1)


def test_a_seven_joint_robot_is_diagnosed_too(repo):
    effects = {'viscous_friction': {'enabled': True, 'coefficient': [0, 0.5, 0, 0, 0, 0, 0]}}
    config = twin_config(
        15.0,
        effects,
        seed=SEED,
        robot=str(repo / 'config/panda.yaml'),
        measurement={'current_noise_std_a': 0.05, 'velocity_noise_std': 0.001},
    )
    twin = simulate(config)
    settings = DiagnosisConfig(effects=('viscous_friction', 'coulomb_friction', 'torque_offset'))
    result = run_diagnosis(twin.recording, config.robot, settings)
    assert len(result.joints) == 7
    assert named(result) == {('viscous_friction', 'panda_joint2')}
    assert result.effects[0].coefficients[0] == pytest.approx(0.5, rel=0.1)
    # The summary's table keeps the 12-character names apart, each over its figures.
    lines = render_summary(result).splitlines()
    head, nominal = lines[lines.index('waterfall:') + 1 :][:2]
    assert head.split()[-7:] == list(result.joints)
    ends = [[m.end() for m in re.finditer(r'\S+', line)][-7:] for line in (head, nominal)]
    assert ends[0] == ends[1]


def test_cogging_above_the_cut_off_is_untestable_not_absent():
    amplitude = [6.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    config, twin = hidden({'cogging': {'enabled': True, 'amplitude': amplitude}})
    result = run_diagnosis(twin.recording, config.robot)
    assert ('cogging', 'joint_1') in result.untestable_effects()
    entry = next(
        u for u in result.untestable if u['name'] == 'cogging' and u['joint'] == 'joint_1'
    )
    assert 'cut-off' in entry['reason']
    assert named(result) == set()


def test_a_too_short_recording_is_refused(short_twin):
    config, twin = short_twin
    with pytest.raises(DatasetError, match='too short'):
        run_diagnosis(twin.recording, config.robot)


def test_a_recording_of_another_robot_is_refused(short_twin):
    config, twin = short_twin
    renamed = replace(twin.recording, joints=tuple(f'axis_{k}' for k in range(6)))
    with pytest.raises(DatasetError, match='do not match the robot config'):
        run_diagnosis(renamed, config.robot)


def test_unknown_effects_in_the_config_are_refused():
    with pytest.raises(ConfigError, match='unknown effect'):
        DiagnosisConfig(effects=('viscous_friction', 'magic_friction'))
    with pytest.raises(ConfigError, match='significance'):
        DiagnosisConfig(significance=0.0)


@pytest.mark.parametrize('whole', [False, True], ids=['rigid-body forms', 'whole-model forms'])
def test_the_folded_one_sample_torque_equals_the_batch_torque(mabi, whole):
    """Every kind of term and form at once, several per effect, against AugmentedModel.torque.

    Viscous laws linear, linear plus a power and a power alone side by side; with ``whole``, a
    torque-constant error and a delay of the whole model's form and a payload body with its own
    inertia.
    """
    rng = np.random.default_rng(3)
    joints = mabi.joints
    terms = []
    scale = {'of': 'model'} if whole else {}
    # (settings, coefficients) of each viscous law
    viscous: list[tuple[dict, int]] = [
        ({}, 1),
        ({'exponent': 1.4}, 1),
        ({'exponent': 0.6, 'linear': True}, 2),
    ]
    for j, joint in enumerate(joints):
        terms += [
            (EffectSpec('viscous_friction', j, joint, viscous[j % 3][0]),
             rng.normal(size=viscous[j % 3][1])),
            (EffectSpec('coulomb_friction', j, joint, {'smoothing_velocity': 0.005}),
             rng.normal(size=1)),
            (EffectSpec('stribeck_friction', j, joint,
                           {'velocity': 0.02 + 0.01 * j, 'smoothing_velocity': 0.005}),
             rng.normal(size=1)),
            (EffectSpec('load_dependent_friction', j, joint, {'smoothing_velocity': 0.004}),
             rng.normal(size=1)),
            (EffectSpec('rotor_inertia', j, joint), rng.normal(size=1) * 1e-4),
            (EffectSpec('torque_constant_scale', j, joint, scale), rng.normal(size=1) * 0.01),
            (EffectSpec('torque_offset', j, joint), rng.normal(size=1)),
            (EffectSpec('cogging', j, joint, {'periods_per_motor_turn': 6}),
             rng.normal(size=2)),
        ]  # fmt: skip
    terms += [
        (EffectSpec('gravity_spring', 1, joints[1], {'reference_rad': 0.0, 'degree': 3}),
         rng.normal(size=3)),
        (EffectSpec('gravity_spring', 2, joints[2], {'ratio': 0.6, 'phase_rad': 0.01}),
         rng.normal(size=3) * 100),
        (EffectSpec('load_dependent_friction', 4, joints[4],
                    {'smoothing_velocity': 0.004, 'load': 'model'}), np.array([0.03])),
        (EffectSpec('joint_offset', 2, joints[2]), rng.normal(size=1) * 1e-3),
        (EffectSpec('signal_delay', settings={'rate_of': 'model'} if whole else {}),
         np.array([0.004])),
        (EffectSpec('payload_mass', settings={'frame': mabi.payload_frame,
                                                 'com_guess_m': [0.1, 0.0, 0.05],
                                                 'inertia': whole}),
         np.array([20.0, 2.0, 0.0, 1.0, *([0.3, 0.0, 0.4, 0.0, 0.0, 0.5] if whole else [])])),
    ]  # fmt: skip
    model = AugmentedModel(mabi, 'motor', terms)
    one = model.sample_function()
    q, v, a = (rng.uniform(-1.0, 1.0, (6, len(joints))) for _ in range(3))
    batch = model.torque(q, v, a)
    for k in range(len(q)):
        np.testing.assert_allclose(one(q[k], v[k], a[k]), batch[k], rtol=1e-12, atol=1e-9)


def test_model_load_friction_sees_the_link_side_terms(mabi):
    """Model-load friction grows with the link torque, the payload included."""
    rng = np.random.default_rng(5)
    q, v, a = (rng.uniform(-1.0, 1.0, (20, 6)) for _ in range(3))
    payload = EffectSpec('payload_mass', settings={'frame': mabi.payload_frame,
                                                   'com_guess_m': [0.1, 0.0, 0.05]})  # fmt: skip
    mass = np.array([30.0, 3.0, 0.0, 0.6])
    eps = 0.004
    load = EffectSpec('load_dependent_friction', 1, 'joint_2',
                      {'smoothing_velocity': eps, 'load': 'model'})  # fmt: skip
    base = AugmentedModel(mabi, 'motor', [])
    with_payload = AugmentedModel(mabi, 'motor', [(payload, mass)])
    full = AugmentedModel(mabi, 'motor', [(payload, mass), (load, np.array([0.05]))])
    # The link torque with the payload, independently: its difference to the URDF's plus the
    # URDF's rigid-body torque (rotor terms are motor-side and not part of the load).
    rigid = base.nominal.evaluate(q, v, a).tau_rigid
    link = rigid + with_payload.torque(q, v, a) - base.torque(q, v, a)
    friction = 0.05 * np.abs(link[:, 1]) * np.tanh(v[:, 1] / eps)
    expected = with_payload.torque(q, v, a)
    expected[:, 1] += friction
    np.testing.assert_allclose(full.torque(q, v, a), expected, rtol=1e-10, atol=1e-8)


def test_a_balancer_is_named_with_its_geometry():
    config, twin = hidden({'gravity_spring': {'enabled': True}})
    spring = config.effects.get('gravity_spring')
    result = run_diagnosis(twin.recording, config.robot)
    assert named(result) == {('gravity_spring', 'joint_2')}
    parameters = {p['name']: p['value'] for p in result.effects[0].parameters}
    assert parameters['arm_ratio'] == pytest.approx(
        spring.arm_base_m / spring.arm_link_m, abs=0.08
    )
    assert parameters['phase'] == pytest.approx(spring.phase_rad, abs=0.02)
    # Its torque over the joint's range against the twin's: the spring's torque helps the
    # motor, which needs that much less.
    q = np.zeros((50, 6))
    q[:, 1] = np.linspace(-1.0, 1.0, 50)
    model = result.augmented_model
    nominal = AugmentedModel(config.robot, 'motor', [])
    found = (model.torque(q, 0 * q, 0 * q) - nominal.torque(q, 0 * q, 0 * q))[:, 1]
    truth = -spring.torque_on_joint(q[:, 1])
    assert np.sqrt(np.mean((found - truth) ** 2)) < 0.05 * np.sqrt(np.mean(truth**2))


def test_load_dependent_friction_takes_the_payload_into_its_load():
    payload = {'enabled': True, 'mass_kg': 40.0, 'com_m': [0.16, 0.0, 0.02]}
    load = {'enabled': True, 'coefficient': [0.0, 0.03, 0.0, 0.0, 0.0, 0.0]}
    config, twin = hidden({'payload_mass': payload, 'load_dependent_friction': load})
    result = run_diagnosis(twin.recording, config.robot)
    assert named(result) == {('payload_mass', None), ('load_dependent_friction', 'joint_2')}
    friction = next(e for e in result.effects if e.name == 'load_dependent_friction')
    assert friction.spec.settings['load'] == 'model'
    assert friction.coefficients[0] == pytest.approx(0.03, rel=0.1)


def test_a_robot_without_a_spring_gets_none_and_no_joint_is_made_worse():
    """Offsets and link-parameter errors bend the gravity torque as a spring would; held-out
    blocks of time do not confirm a spring, and every joint ends no worse than nominal."""
    config, twin = hidden(
        {
            'joint_offset': {'enabled': True},
            'inertial_parameter_error': {'enabled': True},
            'coulomb_friction': {'enabled': True},
        }
    )
    result = run_diagnosis(twin.recording, config.robot)
    assert not [e for e in result.effects if e.name == 'gravity_spring']
    assert (result.rmse_after_nm <= result.rmse_before_nm * (1 + 1e-12)).all()
    for effect in result.effects:
        if effect.confidence == 'high':
            blocks = effect.selection['held_out_blocks']
            assert blocks['p_value_holm'] is not None
            assert blocks['p_value_holm'] < result.settings.significance


def test_joint_torque_sensors_offer_no_motor_side_effects():
    """A torque measured after the gear holds no motor torque constant; an inertia error
    about a joint axis is described link side."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.diagnosis.config import DiagnosisConfig

    config = twin_config(DURATION_S, {'coulomb_friction': {'enabled': True}}, seed=SEED)
    twin = simulate(replace(config, joint_torque_sensors=True))
    settings = DiagnosisConfig(preprocess=PreprocessConfig(target='joint'))
    result = run_diagnosis(twin.recording, config.robot, settings)
    reasons = {(u['name'], u['joint']): u['reason'] for u in result.untestable}
    for j in config.robot.joints:
        assert 'after the gear' in reasons[('torque_constant_scale', j)]
        assert ('rotor_inertia', j) not in reasons or 'after the gear' not in reasons[
            ('rotor_inertia', j)
        ]
    assert 'torque_constant_scale' not in {e.name for e in result.effects}
    for effect in result.effects:
        if effect.name == 'rotor_inertia':
            assert [p['name'] for p in effect.parameters] == ['axis_inertia_change_link_side']


def test_an_alias_set_says_what_motion_would_tell_its_members_apart(tmp_path):
    """An encoder offset on joint 2 that link parameters mimic: where do they differ?"""
    config, twin = hidden({'joint_offset': {'enabled': True, 'offset': [0, 0.004, 0, 0, 0, 0]}})
    result = diagnose(twin.recording, config.robot, out_dir=tmp_path)
    assert result.alias_sets
    for alias in result.alias_sets:
        assert set(alias.separation) == set(alias.alternatives())
        for separation in alias.separation.values():
            assert separation['joint'] in config.robot.joints
            assert separation['feature'] in ('speed', 'acceleration', 'position')
            low, high = separation['range']
            assert low <= high
            assert separation['difference_rms_nm'] > 0
            # The largest of four equal-count bins is at least the whole part's RMS.
            assert separation['ratio_to_overall'] >= 1.0 - 1e-9
    assert 'to tell apart: more motion of' in (tmp_path / 'report.md').read_text(encoding='utf-8')
    data = json.loads((tmp_path / 'effects.json').read_text(encoding='utf-8'))
    assert data['alias_sets'][0]['separating_motion']


def test_a_wrist_encoder_zero_several_degrees_off_is_kept_with_its_link_parameter_alias():
    """Six degrees on joint 5 move the flange 2.4 cm (a wrist mastered by eye): plausible. The
    wrist's centre of mass turned about the axis looks the same to gravity, so the link
    parameters stand beside it as its alias, and nothing else is named."""
    config, twin = hidden({'joint_offset': {'enabled': True, 'offset': [0, 0, 0, 0, 0.1, 0]}})
    result = run_diagnosis(twin.recording, config.robot)
    assert result.named_effects() == []
    (alias,) = result.alias_sets
    assert alias.representative == 'joint_offset[joint_5]'
    assert alias.alternatives() == ['inertial_parameter_error']
    (offset,) = result.effects
    low, high = offset.parameters[0]['ci']
    assert low <= 0.1 <= high
