"""The forms of an effect family: a spring's geometries, the loads friction grows with.

Each form's columns against its closed form, and what it reports against the values that made
the torque.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pinocchio_reference import G_WORLD, reference_model, velocity_index

from id_learning.physics import AugmentedModel, EffectSpec, NominalModel, effect_columns
from id_learning.physics.effects import effect
from id_learning.physics.effects.base import FittedTerm
from id_learning.physics.effects.judgement import CandidateGrid

J = 1  # joint_2: gravity acts there


@pytest.fixture(scope='module')
def model(mabi):
    return NominalModel(mabi)


@pytest.fixture(scope='module')
def quantities(model):
    rng = np.random.default_rng(31)
    limits = model.robot.limits
    q = rng.uniform(limits.position_lower, limits.position_upper, (200, model.robot.n_joints))
    v = rng.normal(0.0, 0.5, q.shape)
    return model.evaluate(q, v, rng.normal(0.0, 2.0, q.shape), gravity=True)


def column(model, quantities, name: str, **form) -> np.ndarray:
    columns = effect_columns(EffectSpec(name, J, model.robot.joints[J], form), quantities, model)
    assert not np.delete(columns, J, axis=1).any()  # the joint's own torque only
    return columns[:, J, :]


@settings(max_examples=40, deadline=None)
@given(moment=st.floats(0.5, 200.0), phase=st.floats(-math.pi, math.pi))
def test_a_counterweight_reports_the_moment_and_phase_that_made_its_torque(
    model, quantities, moment, phase
):
    """-m r g cos(q + phi) lies in the counterweight's columns; its coefficients read back as m r
    and phi (the phase modulo a turn)."""
    q = quantities.q[:, J]
    torque = -moment * np.linalg.norm(G_WORLD) * np.cos(q + phase)
    x = column(model, quantities, 'gravity_spring', form='counterweight')
    theta, *_ = np.linalg.lstsq(x, torque, rcond=None)
    np.testing.assert_allclose(x @ theta, torque, atol=1e-8 * moment)
    fit = FittedTerm(J, {'form': 'counterweight'}, theta, np.full(2, 1e-3))
    described = {p['name']: p for p in effect('gravity_spring').describe(fit, model)}
    assert described['moment']['value'] == pytest.approx(moment, rel=1e-9)
    assert described['moment']['unit'] == 'kg*m'
    turn = (described['phase']['value'] - phase + math.pi) % (2 * math.pi) - math.pi
    assert abs(turn) < 1e-9
    low, high = described['moment']['ci']
    assert low < moment < high


def test_a_torsion_spring_reports_its_stiffness_and_neutral(model, quantities):
    """-k (q - q0) lies in its two columns about the reference; k and q0 read back, each inside
    its interval."""
    q = quantities.q[:, J]
    k, neutral, reference = 150.0, 0.4, -0.2
    x = column(model, quantities, 'gravity_spring', form='torsion', reference_rad=reference)
    np.testing.assert_allclose(x[:, 0], q - reference)
    theta = np.linalg.lstsq(x, -k * (q - neutral), rcond=None)[0]
    settings = {'form': 'torsion', 'reference_rad': reference}
    fit = FittedTerm(J, settings, theta, np.array([2.0, 1.0]))
    described = {p['name']: p for p in effect('gravity_spring').describe(fit, model)}
    assert described['stiffness']['value'] == pytest.approx(k)
    assert described['stiffness']['ci'] == pytest.approx([k - 2.0, k + 2.0])
    assert described['neutral']['value'] == pytest.approx(neutral)
    low, high = described['neutral']['ci']
    assert low < neutral < high


def test_load_dependent_friction_grows_with_gravity_in_its_gravity_form(model, quantities):
    """|g(q)| tanh(v / v_eps), g from pinocchio directly; the link-torque form reads RNEA."""
    eps = 0.01
    reference = reference_model(model.robot)
    data = reference.createData()
    index = velocity_index(reference, model.robot.joints)
    gravity = np.empty(len(quantities.q))
    for k, qk in enumerate(quantities.q):
        q_pin = np.zeros(reference.nq)
        q_pin[index] = qk
        gravity[k] = pin.computeGeneralizedGravity(reference, data, q_pin)[index[J]]
    v = quantities.v[:, J]
    x = column(
        model, quantities, 'load_dependent_friction', smoothing_velocity=eps, load='gravity'
    )
    np.testing.assert_allclose(x[:, 0], np.abs(gravity) * np.tanh(v / eps), rtol=1e-9)
    link = column(model, quantities, 'load_dependent_friction', smoothing_velocity=eps)
    np.testing.assert_allclose(
        link[:, 0], np.abs(quantities.tau_rigid[:, J]) * np.tanh(v / eps), rtol=1e-9
    )
    assert not np.allclose(x, link)


def test_every_form_is_a_candidate_with_a_label_of_its_own(model):
    """A family's forms on one joint are exclusive variants the diagnosis tells apart by label."""
    grid = CandidateGrid(0.005, (0.05,), (6,), (J,))
    for name in ('gravity_spring', 'load_dependent_friction'):
        item = effect(name)
        assert item.exclusive_variants
        on_joint = [s for j, s in item.candidates(model, grid) if j == J]
        labels = {EffectSpec(name, J, model.robot.joints[J], s).label for s in on_joint}
        assert len(labels) == len(on_joint) >= 2, name
    forms = {
        s.get('form', 'balancer') for j, s in effect('gravity_spring').candidates(model, grid)
    }
    assert forms == {'balancer', 'counterweight', 'torsion'}
    limits = model.robot.limits
    by_form = {s.get('form'): s for _, s in effect('gravity_spring').candidates(model, grid)}
    torsion = by_form['torsion']
    assert limits.position_lower[J] < torsion['reference_rad'] < limits.position_upper[J]


def test_only_the_link_torque_form_moves_to_the_whole_models_load():
    """Friction growing with gravity stays with the URDF's gravity; the link torque's form takes
    the whole model's link torque."""
    item = effect('load_dependent_friction')
    assert item.model_load_settings({'smoothing_velocity': 0.01}) == {
        'smoothing_velocity': 0.01, 'load': 'model'
    }  # fmt: skip
    assert item.model_load_settings({'smoothing_velocity': 0.01, 'load': 'gravity'}) is None
    assert effect('coulomb_friction').model_load_settings({}) is None


def test_every_form_carries_into_a_saved_model_and_its_online_torque(model, quantities):
    """A model of the diagnosis's forms (rnea_effects) gives the same torque batch and per
    sample, and after a round trip through its JSON."""
    robot = model.robot
    terms = [
        (EffectSpec('gravity_spring', 1, robot.joints[1], {'form': 'counterweight'}),
         np.array([100.0, -50.0])),
        (EffectSpec('gravity_spring', 2, robot.joints[2],
                    {'form': 'torsion', 'reference_rad': -0.5}), np.array([-30.0, 5.0])),
        (EffectSpec('load_dependent_friction', 1, robot.joints[1],
                    {'smoothing_velocity': 0.005, 'load': 'gravity'}), np.array([0.02])),
    ]  # fmt: skip
    augmented = AugmentedModel(robot, 'motor', terms)
    q, v, a = quantities.q[:30], quantities.v[:30], quantities.a[:30]
    batch = augmented.torque(q, v, a)
    expected = quantities.tau_nominal[:30] + sum(
        effect_columns(spec, model.evaluate(q, v, a, gravity=True), model) @ theta
        for spec, theta in terms
    )
    np.testing.assert_allclose(batch, expected, rtol=1e-12, atol=1e-9)
    one = augmented.sample_function()
    np.testing.assert_allclose([one(*row) for row in zip(q, v, a, strict=True)], batch, atol=1e-9)
    again = AugmentedModel.from_dict(augmented.to_dict(), robot)
    np.testing.assert_allclose(again.torque(q, v, a), batch, atol=1e-12)
