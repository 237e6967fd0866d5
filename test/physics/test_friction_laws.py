"""The friction laws, once: closed-form properties, and every user of a law gets the same torque.

The twin's true robot, the diagnosis's candidate columns and the identification's columns all
take their law from ``physics.friction``; a sign or shape error there fails here, in one place.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from id_learning.physics import friction
from id_learning.physics.identified import friction_columns
from id_learning.physics.terms import JOINT_COLUMNS
from id_learning.twin.effects import (
    CoulombFriction,
    LoadDependentFriction,
    StribeckFriction,
    ViscousFriction,
)

EPS = 0.005
velocities = arrays(float, (40, 3), elements=st.floats(-3.0, 3.0, allow_nan=False))
loads = arrays(float, (40, 3), elements=st.floats(-5e3, 5e3, allow_nan=False))


@given(velocities)
def test_coulomb_is_odd_bounded_and_the_sign_away_from_rest(v):
    column = friction.coulomb(v, EPS)
    np.testing.assert_allclose(friction.coulomb(-v, EPS), -column, atol=1e-15)
    assert np.all(np.abs(column) <= 1.0)
    fast = np.abs(v) > 10 * EPS
    np.testing.assert_allclose(column[fast], np.sign(v[fast]), atol=1e-8)


@given(velocities)
def test_stribeck_fades_with_speed_and_is_e_inverse_at_its_velocity(v):
    vs = 0.05
    column = friction.stribeck(v, vs, EPS)
    assert np.all(np.abs(column) <= np.abs(friction.coulomb(v, EPS)) + 1e-15)
    at = friction.stribeck(np.array([vs]), vs, EPS)
    np.testing.assert_allclose(at, np.exp(-1.0) * np.tanh(vs / EPS))


@given(velocities, loads)
def test_load_dependent_grows_with_the_load_magnitude_and_its_slope_is_its_derivative(v, load):
    column = friction.load_dependent(v, load, EPS)
    np.testing.assert_allclose(friction.load_dependent(v, -load, EPS), column)
    step = 1e-3
    away = np.abs(load) > 2 * step  # |L| is not differentiable at 0
    numeric = (
        friction.load_dependent(v, load + step, EPS) - friction.load_dependent(v, load - step, EPS)
    ) / (2 * step)
    np.testing.assert_allclose(
        friction.load_slope(v, load, EPS)[away], numeric[away], rtol=1e-6, atol=1e-9
    )


def test_viscous_power_law_bends_and_keeps_the_sign():
    v = np.array([-2.0, -0.5, 0.0, 0.5, 2.0])
    (linear,) = friction.viscous(v)
    np.testing.assert_array_equal(linear, v)
    both = friction.viscous(v, 0.5, linear=True)
    np.testing.assert_array_equal(both[0], v)
    np.testing.assert_allclose(both[1], np.sign(v) * np.sqrt(np.abs(v)))


def test_warm_up_starts_at_one_and_settles_at_the_warm_scale():
    scale = friction.warm_up(0.6, 100.0, np.array([0.0, 100.0, 1e6]))
    np.testing.assert_allclose(np.ravel(scale), [1.0, 0.6 + 0.4 * np.exp(-1.0), 0.6])
    assert friction.warm_up(0.6, 0.0, np.array([5.0])) == 1.0


@settings(max_examples=25)
@given(velocities, loads)
def test_the_twin_the_diagnosis_and_the_identification_model_the_same_friction(v, load):
    coefficient = np.array([3.0, 0.7, 12.0])
    vs = np.array([0.02, 0.05, 0.1])
    twin = {
        'viscous': ViscousFriction(True, coefficient).torque(v),
        'coulomb': CoulombFriction(True, coefficient, EPS).torque(v),
        'stribeck': StribeckFriction(True, coefficient, vs, EPS).torque(v),
        'load_dependent': LoadDependentFriction(True, coefficient, EPS).torque(v, load),
    }
    identified = friction_columns(tuple(twin), v, load, EPS, vs)
    quantities = SimpleNamespace(v=v, tau_rigid=load)
    joints = np.arange(3)
    for law, torque in twin.items():
        np.testing.assert_allclose(coefficient * identified[law], torque, rtol=1e-12, atol=1e-12)
        column_settings = {'smoothing_velocity': EPS, 'velocity': vs}
        (column,) = JOINT_COLUMNS[f'{law}_friction'](quantities, joints, column_settings, None)
        np.testing.assert_allclose(coefficient * column, torque, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize('law', ['coulomb', 'stribeck', 'load_dependent'])
def test_a_law_serves_one_sample_as_it_serves_a_batch(law):
    v = np.linspace(-1, 1, 7)
    args = {'coulomb': (EPS,), 'stribeck': (0.05, EPS), 'load_dependent': (np.full(7, 9.0), EPS)}
    batch = getattr(friction, law)(v, *args[law])
    one = [
        getattr(friction, law)(v[k], *[a[k] if np.ndim(a) else a for a in args[law]])
        for k in range(7)
    ]
    np.testing.assert_allclose(batch, one)
