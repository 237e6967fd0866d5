"""The registry of effects: one object per effect, the names the twin and the diagnosis share."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

from id_learning.errors import ConfigError
from id_learning.physics import NominalModel
from id_learning.physics.effects import (
    EFFECT_NAMES,
    FRICTION_LAWS,
    REGISTRY,
    FittedTerm,
    JointEffect,
    effect,
    friction_law,
)
from id_learning.physics.effects.judgement import CandidateGrid, PlausibilityFacts, Trial
from id_learning.physics.effects.links import JOINT_OFFSET, offset_range
from id_learning.physics.terms import EffectSpec, effect_columns
from id_learning.twin.effects import effects_from_dict

#: Settings that make each effect's columns well defined on the MABI (one candidate each).
SETTINGS = {
    'viscous_friction': {},
    'coulomb_friction': {'smoothing_velocity': 0.005},
    'stribeck_friction': {'smoothing_velocity': 0.005, 'velocity': 0.05},
    'load_dependent_friction': {'smoothing_velocity': 0.005},
    'rotor_inertia': {},
    'gravity_spring': {'ratio': 0.6, 'phase_rad': 0.0},
    'torque_constant_scale': {},
    'cogging': {'periods_per_motor_turn': 6},
    'torque_offset': {},
}


def test_every_effect_has_a_unique_name_and_parameters_with_units():
    assert len(REGISTRY) == len(EFFECT_NAMES) == 13
    for item in REGISTRY.values():
        assert item.parameters, item.name
        assert all(p.name and p.unit for p in item.parameters), item.name


def test_the_twin_models_every_effect_of_the_registry(mabi):
    assert tuple(effects_from_dict({}, mabi.joints).effects) == EFFECT_NAMES


def test_an_unknown_effect_is_refused_naming_the_known_ones():
    with pytest.raises(ConfigError, match=r"unknown effect 'spring'; known effects: \['viscous"):
        effect('spring')


def test_a_joint_effect_gives_every_joint_at_once_what_it_gives_each(mabi):
    model = NominalModel(mabi)
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, (50, 6))
    quantities = model.evaluate(q, rng.normal(0, 0.5, q.shape), rng.normal(0, 2, q.shape))
    joints = np.arange(6)
    for name, settings in SETTINGS.items():
        item = effect(name)
        assert isinstance(item, JointEffect)
        together = item.joint_columns(quantities, joints, settings, model)
        for j in range(6):
            alone = effect_columns(
                EffectSpec(name, j, mabi.joints[j], settings), quantities, model
            )
            assert alone.shape[2] == len(together), name
            for c, column in enumerate(together):
                np.testing.assert_allclose(alone[:, j, c], column[:, j], err_msg=name)
                assert not np.delete(alone[:, :, c], j, axis=1).any(), name


def test_labels_tell_candidates_apart_by_their_settings():
    a = EffectSpec('stribeck_friction', 1, 'joint_2', {'velocity': 0.05})
    b = EffectSpec('stribeck_friction', 1, 'joint_2', {'velocity': 0.1})
    assert a.label == 'stribeck_friction[joint_2, v_s=0.05]' != b.label
    whole = EffectSpec('signal_delay', settings=effect('signal_delay').whole_model_settings())
    assert whole.label == 'signal_delay[whole model]'
    with pytest.raises(ValueError, match='coulomb_friction has no whole-model form'):
        effect('coulomb_friction').whole_model_settings()


def test_every_effect_judges_a_fit_and_lists_candidates(mabi):
    """No effect is left to a name dispatch elsewhere: each answers every question itself."""
    model = NominalModel(mabi)
    rng = np.random.default_rng(5)
    q = rng.uniform(-1, 1, (80, 6))
    quantities = model.evaluate(
        q, rng.normal(0, 0.5, q.shape), rng.normal(0, 2, q.shape), derivatives=True,
        regressor=True,
    )  # fmt: skip
    facts = PlausibilityFacts(
        np.ones(6), model.dynamics.gravity(q), 1000.0,
        model.dynamics.inertial_parameters().reshape(-1, 10),
        np.stack([q.min(axis=0), q.max(axis=0)]),
    )  # fmt: skip
    grid = CandidateGrid(0.005, (0.05,), (6,), (1,))
    for name, item in REGISTRY.items():
        assert item.special_case_of in (None, *REGISTRY), name
        candidates = item.candidates(model, grid)
        assert candidates, name
        joint, settings = candidates[0]
        spec = EffectSpec(name, joint, mabi.joints[joint] if joint is not None else '', settings)
        columns = effect_columns(spec, quantities, model)
        k = columns.shape[2]
        trial = Trial(joint, settings, np.zeros(k), np.eye(k), columns)
        ok, reason = item.plausibility(trial, model, facts)
        assert isinstance(ok, bool), name
        assert isinstance(reason, str), name
        described = item.describe(FittedTerm(joint, settings, np.zeros(k), np.ones(k)), model)
        assert all({'name', 'value', 'ci', 'unit'} <= set(p) for p in described), name


def _name_comparisons(source: str) -> list[str]:
    """Comparisons in ``source`` against an effect's name (``x == 'payload_mass'``, ``in``)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            constants = [c.value for c in ast.walk(node) if isinstance(c, ast.Constant)]
            if any(value in EFFECT_NAMES for value in constants):
                out.append(ast.unparse(node))
    return out


def test_no_module_outside_the_registry_decides_by_an_effects_name():
    """What an effect does is asked of its object: a name compared elsewhere is a second home
    for its behaviour (and the check itself sees one when it is there)."""
    assert _name_comparisons("if spec.name in ('payload_mass', 'x'):\n    pass") != []
    package = Path(__file__).resolve().parents[2] / 'id_learning'
    effects = package / 'physics' / 'effects'
    found = {
        str(path.relative_to(package)): hits
        for path in sorted(package.rglob('*.py'))
        if effects not in path.parents and (hits := _name_comparisons(path.read_text()))
    }
    assert found == {}


def test_every_friction_law_of_the_identification_is_an_effects_law():
    v = np.linspace(-1.0, 1.0, 41)[:, None]
    load = np.full_like(v, -250.0)
    for law in FRICTION_LAWS:
        item = friction_law(law)
        assert item.law == law
        assert item.friction_shaped
        column = item.law_column(v, load, 0.01, np.array([0.05]))
        # Each law opposes motion: its column has the sign of v, and is odd in v.
        assert np.all(column * v >= 0)
        np.testing.assert_allclose(column[::-1], -column, atol=1e-12)
    with pytest.raises(ConfigError, match='unknown friction law'):
        friction_law('dry')


@pytest.fixture(scope='module')
def mabi_model(mabi):
    return NominalModel(mabi)


@hypothesis_settings(max_examples=60, deadline=None)
@given(
    joint=st.integers(0, 5),
    low_share=st.floats(-0.2, 1.0),
    span_share=st.floats(0.0, 1.2),
)
def test_an_encoder_offset_may_move_the_measured_angles_only_within_the_limits(
    mabi_model, joint, low_share, span_share
):
    """offset_range: zero always inside; at most the plausible bound either way; and where the
    recording kept inside the limits, every offset in the range keeps it there."""
    limits = mabi_model.robot.limits
    lower, upper = limits.position_lower[joint], limits.position_upper[joint]
    width = upper - lower
    positions = np.zeros((2, 6))
    positions[0, joint] = lower + low_share * width
    positions[1, joint] = positions[0, joint] + span_share * width
    low, high = offset_range(joint, mabi_model, positions)
    assert low <= 0.0 <= high
    bound = JOINT_OFFSET.plausible_bound(joint, mabi_model)
    assert -bound <= low
    assert high <= bound
    if lower <= positions[0, joint] and positions[1, joint] <= upper:
        for offset in (low, high):
            assert lower - 1e-12 <= positions[0, joint] + offset
            assert positions[1, joint] + offset <= upper + 1e-12
    if positions[1, joint] > upper:  # already beyond: no offset pushes it further out
        assert high == 0.0


def test_an_offset_the_limits_leave_room_for_is_plausible_and_one_beyond_is_refused(mabi_model):
    """0.03 rad on a heavy axis recorded 0.1 rad inside its limits is kept; 0.06 is not."""
    limits = mabi_model.robot.limits
    j = 1
    positions = np.zeros((2, 6))
    positions[:, j] = limits.position_lower[j] + 0.1, limits.position_upper[j] - 0.05
    facts = PlausibilityFacts(np.ones(6), np.zeros((3, 6)), 1000.0, np.zeros((6, 10)), positions)
    columns = np.zeros((3, 6, 1))

    def verdict(value: float) -> tuple[bool, str]:
        trial = Trial(j, {}, np.array([value]), np.array([[1e-8]]), columns)
        return JOINT_OFFSET.plausibility(trial, mabi_model, facts)

    assert verdict(0.03)[0]
    assert verdict(-0.09)[0]
    ok, reason = verdict(0.06)
    assert not ok
    assert 'outside the plausible range' in reason
