"""The friction curve's shape the diagnosis identifies, its free torque at standstill, its hump."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from support import twin_config

from id_learning.dataset.preprocess import prepare_dataset
from id_learning.diagnosis import DiagnosisConfig, run_diagnosis
from id_learning.diagnosis.candidate_set import CandidateSet
from id_learning.diagnosis.problem import ResidualProblem, as_datasets
from id_learning.diagnosis.standstill import StandstillProjection, standstill_intervals
from id_learning.errors import ConfigError
from id_learning.robot.drives import current_from_motor_torque
from id_learning.twin import simulate

DURATION_S = 150.0
SEED = 11
COULOMB = [120.0, 160.0, 90.0, 20.0, 15.0, 6.0]
VISCOUS = [300.0, 400.0, 220.0, 45.0, 35.0, 15.0]


def friction(smoothing: float) -> dict:
    return {
        'coulomb_friction': {
            'enabled': True, 'level': COULOMB, 'smoothing_velocity': smoothing
        },
        'viscous_friction': {'enabled': True, 'coefficient': VISCOUS},
    }  # fmt: skip


def shapes_of(recording, robot) -> list[tuple[float, float]]:
    """Per joint, the (v_eps, viscous exponent) the diagnosis identifies."""
    config = DiagnosisConfig()
    problem = ResidualProblem(as_datasets(recording, robot, config), robot, config)
    return CandidateSet(problem).friction_shapes


def test_standstill_intervals_are_the_rests_long_enough():
    v = np.ones(100)
    v[10:30] = 1e-4  # 20 samples at rest
    v[50:53] = 0.0  # 3 samples: a reversal, not a rest
    v[90:] = -1e-4  # a rest to the end
    assert standstill_intervals(v, 0.01, threshold=2e-3, min_s=0.05) == [(10, 30), (90, 100)]
    assert standstill_intervals(np.ones(10), 0.01, 2e-3, 0.05) == []


def test_standstill_projection_removes_a_held_torque_and_nothing_else(short_twin):
    config, twin = short_twin
    dataset = prepare_dataset(twin.recording, config.robot)
    n_samples, n = dataset.v.shape
    rows = {'train': np.arange(n_samples), 'test': np.arange(0)}
    projection = StandstillProjection([(dataset, rows)], threshold=2e-3, min_s=0.1)
    assert projection.counts['train'].sum() > 0
    assert projection.counts['test'].sum() == 0  # no held-out rows
    j = int(np.argmax(projection.counts['train']))
    basis = projection.bases['train'][j]
    assert basis is not None
    held = 7.0 * basis[:, 0] + 3.0 * basis[:, -1]
    y = np.zeros((n_samples, n))
    y[:, j] = held + np.sin(np.arange(n_samples) * 0.01)
    projected = projection.project(y)
    # What remains is orthogonal to every standstill box and the sine's share outside them.
    assert np.abs(basis.T @ projected[:, j]).max() < 1e-8
    sine = np.sin(np.arange(n_samples) * 0.01)
    assert projected[:, j] == pytest.approx(sine - basis @ (basis.T @ sine), abs=1e-9)


def test_the_twins_sign_smoothing_is_kept_and_a_sharp_one_is_found():
    smooth = twin_config(DURATION_S, friction(0.005), seed=SEED)
    assert shapes_of(simulate(smooth).recording, smooth.robot) == [(0.005, 1.0)] * 6

    sharp = twin_config(DURATION_S, friction(0.0005), seed=SEED)
    shapes = shapes_of(simulate(sharp).recording, sharp.robot)
    # The two heaviest axes' large Coulomb levels show the sharp turn clearly; no joint is
    # given a softer turn or a curved viscous law.
    assert all(eps <= 0.001 for eps, _ in shapes[:2])
    assert all(eps <= 0.005 and exponent == 1.0 for eps, exponent in shapes)


STRIBECK = [70.0, 90.0, 50.0, 10.0, 8.0, 3.0]
STRIBECK_VELOCITY = [0.03, 0.03, 0.03, 0.05, 0.05, 0.05]


def with_stribeck() -> dict:
    """Twin-form friction with humps at 30 mrad/s (joints 1-3) and 50 mrad/s (joints 4-6)."""
    return friction(0.005) | {
        'stribeck_friction': {
            'enabled': True, 'level': STRIBECK, 'velocity': STRIBECK_VELOCITY,
            'smoothing_velocity': 0.005,
        }
    }  # fmt: skip


def test_stribeck_level_intervals_hold_what_the_refined_velocity_leaves_unknown():
    # The level and the velocity, refined on the same data, trade; with the velocity taken as
    # exact joint 5's interval [8.01, 10.30] N*m missed its 8 N*m. Read again beside the values'
    # fit, each velocity carries an interval of its own, which holds the truth.
    config = twin_config(DURATION_S, with_stribeck(), seed=SEED)
    result = run_diagnosis(simulate(config).recording, config.robot)
    humps = [e for e in result.effects if e.name == 'stribeck_friction']
    assert len(humps) == 6
    held = 0
    for hump in humps:
        level, velocity = hump.parameters
        held += level['ci'][0] <= STRIBECK[hump.spec.joint] <= level['ci'][1]
        true_velocity = STRIBECK_VELOCITY[hump.spec.joint]
        assert velocity['ci'][0] <= true_velocity <= velocity['ci'][1], hump.label
        assert velocity['ci'][1] - velocity['ci'][0] > 0.05 * true_velocity, hump.label
    # Six 95 % intervals all hold the truth on 74 % of recordings: at least five of six.
    # (Here joint 5 reads 9.2 [8.2, 10.2] on its 150 s, 9.1 [8.0, 10.3] on the training part.)
    assert held >= 5


@pytest.mark.parametrize('true_exponent', [1.4, 0.6], ids=['stiffening', 'thinning'])
def test_a_curved_viscous_law_is_identified_and_named_alone(true_exponent):
    config = twin_config(DURATION_S, friction(0.005), seed=SEED)
    twin = simulate(config)
    # Joint 1's viscous law grows as |v|^delta instead of linearly: add the difference.
    extra = np.zeros_like(twin.v_true)
    v = twin.v_true[:, 0]
    extra[:, 0] = VISCOUS[0] * (np.sign(v) * np.abs(v) ** true_exponent - v)
    recording = replace(
        twin.recording,
        current=twin.recording.current + current_from_motor_torque(extra, config.robot.drives),
    )
    shapes = shapes_of(recording, config.robot)
    assert shapes[0][1] != 1.0
    assert (shapes[0][1] > 1.0) == (true_exponent > 1.0)
    assert shapes[1:] == [(0.005, 1.0)] * 5
    result = run_diagnosis(recording, config.robot)
    names = {e.name for e in result.named_effects()}
    assert names <= {'viscous_friction', 'coulomb_friction'}
    (viscous,) = [e for e in result.effects if e.label.startswith('viscous_friction[joint_1')]
    # Stiffening: a linear part plus a power (of the grid's exponents, not necessarily the
    # true one); thinning: a power alone. Either draws the true curve over the speeds reached.
    exponent = viscous.spec.settings['exponent']
    assert bool(viscous.spec.settings.get('linear')) == (true_exponent > 1.0)
    speeds = np.linspace(0.0, np.abs(v).max(), 50)
    basis = [speeds, speeds**exponent] if exponent > 1.0 else [speeds**exponent]
    fitted = viscous.coefficients @ np.stack(basis)
    true = VISCOUS[0] * speeds**true_exponent
    assert np.abs(fitted - true).max() < 0.03 * true.max()


def test_friction_shape_grids_are_checked():
    with pytest.raises(ConfigError, match='viscous_exponents'):
        DiagnosisConfig(viscous_exponents=(0.0,))
    with pytest.raises(ConfigError, match='smoothing_velocities'):
        DiagnosisConfig(smoothing_velocities=(-1.0,))
    with pytest.raises(ConfigError, match='standstill_velocity'):
        DiagnosisConfig(standstill_velocity=-1.0)


def _refined_shape(recording, robot, joint: int, judged: tuple[float, float]):
    """Joint ``joint`` given the ``judged`` shape, its twin friction and a hump at 50 mrad/s
    selected (every other joint's too), then refined: the joint's shape and refined hump."""
    config = DiagnosisConfig()
    problem = ResidualProblem(as_datasets(recording, robot, config), robot, config)
    candidates = CandidateSet(problem)
    if candidates.friction_shapes[joint] != judged:
        candidates.friction_shapes[joint] = judged
        candidates._reshape(joint, judged, list(candidates.testable))
    specs = candidates.specs
    selected = [
        g
        for g in candidates.testable
        if specs[g].name in ('viscous_friction', 'coulomb_friction')
        or (specs[g].name == 'stribeck_friction' and specs[g].settings['velocity'] == 0.05)
    ]
    y = {part: problem.residual(part) for part in ('train', 'test')}
    n_eff = {part: problem.n_effective(part) for part in ('train', 'test')}
    refined = candidates.refine(selected, y, n_eff)
    (hump,) = [
        specs[g]
        for g in refined
        if specs[g].name == 'stribeck_friction' and specs[g].joint == joint
    ]
    return candidates.friction_shapes[joint], hump


def test_a_curved_viscous_law_taken_for_a_hump_is_judged_again_beside_it():
    # Twin seed 15 at 600 s with every effect: joint 3's law was judged |v|^0.8 beside humps at
    # 15 and 50 mrad/s, its 30 mrad/s hump refined to 51 mrad/s and the Coulomb level read 93
    # for 120. Beside the hump at its own velocity the twin's linear law is found again.
    config = twin_config(DURATION_S, with_stribeck(), seed=SEED)
    recording = simulate(config).recording
    shape, hump = _refined_shape(recording, config.robot, 2, (0.005, 0.8))
    assert shape == (0.005, 1.0)
    assert hump.settings['velocity'] == pytest.approx(0.03, rel=0.15)


def test_a_curved_viscous_law_that_is_there_survives_the_hump_beside_it():
    config = twin_config(DURATION_S, with_stribeck(), seed=SEED)
    twin = simulate(config)
    extra = np.zeros_like(twin.v_true)
    v = twin.v_true[:, 0]
    extra[:, 0] = VISCOUS[0] * (np.sign(v) * np.abs(v) ** 0.6 - v)
    recording = replace(
        twin.recording,
        current=twin.recording.current + current_from_motor_torque(extra, config.robot.drives),
    )
    shape, hump = _refined_shape(recording, config.robot, 0, (0.005, 0.6))
    assert shape[1] == 0.6
    assert hump.settings['velocity'] == pytest.approx(0.03, rel=0.15)
