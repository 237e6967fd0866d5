"""The diagnosis' candidate library."""

from __future__ import annotations

import numpy as np

from id_learning.diagnosis import DiagnosisConfig
from id_learning.diagnosis.candidates import PlausibilityFacts, build_library, plausibility
from id_learning.diagnosis.parameters import describe_parameters
from id_learning.physics import EFFECT_NAMES, EffectSpec, NominalModel
from id_learning.twin.effects import EFFECT_NAMES as TWIN_EFFECT_NAMES


def test_library_names_every_effect_once_per_joint_or_robot_wide(mabi):
    model = NominalModel(mabi)
    rng = np.random.default_rng(0)
    limits = mabi.limits
    q = rng.uniform(limits.position_lower, limits.position_upper, (200, mabi.n_joints))
    v = rng.uniform(-1, 1, q.shape) * limits.velocity
    quantities = model.evaluate(q, v, np.zeros_like(q))

    library = build_library(model, quantities, DiagnosisConfig())
    names = {s.name for s in library}
    assert names == set(EFFECT_NAMES)
    # The physics layer names exactly the effects the twin can hide, in the same order.
    assert EFFECT_NAMES == TWIN_EFFECT_NAMES
    labels = [s.label for s in library]
    assert len(labels) == len(set(labels))
    config = DiagnosisConfig(effects=('viscous_friction', 'torque_offset'))
    assert len(build_library(model, quantities, config)) == 2 * model.robot.n_joints


def test_a_balancer_is_plausible_when_it_takes_load_off_on_average(mabi):
    """A balancer on joint 3 turns with q3, gravity there with q2 + q3: along a motion their
    shapes may rise together while the balancer still carries weight (its torque's mean against
    gravity's). It balances when it falls where gravity rises or takes load off on average."""
    model = NominalModel(mabi)
    t = np.linspace(0.0, 20.0, 2001)
    gravity = np.zeros((len(t), mabi.n_joints))
    gravity[:, 2] = -400.0 + 300.0 * np.sin(t)
    facts = PlausibilityFacts(
        np.ones(mabi.n_joints), gravity, 1000.0, np.zeros((6, 10)), np.zeros((2, 6))
    )
    spec = EffectSpec('gravity_spring', 2, mabi.joints[2], {'ratio': 0.5, 'phase_rad': 0.0})

    def verdict(spring: np.ndarray, sd: float = 0.0) -> tuple[bool, str]:
        columns = np.zeros((*gravity.shape, 3))
        columns[:, 2, 0] = spring
        covariance = np.diag([sd**2, 0.0, 0.0])
        return plausibility(
            spec, np.array([1.0, 0, 0]), columns, model, facts, covariance=covariance
        )

    shape = 20.0 * np.sin(t)  # rises with gravity's shape (correlation +1 about the means)
    assert verdict(30.0 + shape)[0]
    assert verdict(-30.0 - shape)[0]  # adds on average, but falls where gravity rises
    ok, reason = verdict(-30.0 + shape)
    assert not ok
    assert 'add to gravity' in reason
    # Adding to gravity by less than its uncertainty says: not refused for its noise.
    assert verdict(-30.0 + shape, sd=0.5)[0]
    assert not verdict(-30.0 + shape, sd=0.1)[0]


def test_a_viscous_law_with_a_linear_part_must_dissipate_within_the_torque_limit(mabi):
    """b v + c v^delta: any sign of b or c, as long as the torque opposes the motion at every
    speed up to the limit and stays below the torque limit there, beyond its margin."""
    model = NominalModel(mabi)
    j = 1
    facts = PlausibilityFacts(
        np.ones(mabi.n_joints), np.zeros((10, 6)), 1000.0, np.zeros((6, 10)), np.zeros((2, 6))
    )
    top, limit = mabi.limits.velocity[j], mabi.limits.torque[j]
    columns = np.zeros((1, mabi.n_joints, 2))

    def verdict(b: float, c: float, sd: float = 0.0, exponent: float = 1.4) -> tuple[bool, str]:
        spec = EffectSpec(
            'viscous_friction', j, mabi.joints[j], {'exponent': exponent, 'linear': True}
        )
        covariance = np.diag([sd**2, 0.0])
        return plausibility(spec, np.array([b, c]), columns, model, facts, covariance=covariance)

    assert verdict(500.0, -50.0)[0]  # bends down at speed, still dissipative everywhere
    # Bends so far that at the top speed it would drive the joint.
    c = -2.0 * 500.0 * top / top**1.4
    ok, reason = verdict(500.0, c)
    assert not ok
    assert 'drives the joint' in reason
    assert verdict(500.0, c, sd=1e4)[0]  # ... unless the data cannot tell
    ok, reason = verdict(2.0 * limit / top, 0.0)
    assert not ok
    assert 'torque limit' in reason
    # Within the limit at the top speed, beyond it on the way: 1.26 times it at 0.63 of it.
    b, c = 3.0 * limit / top, -2.5 * limit / top**3
    assert b * top + c * top**3 < limit
    ok, reason = verdict(b, c, exponent=3.0)
    assert not ok
    assert 'torque limit' in reason


def test_a_viscous_law_names_its_terms(mabi):
    model = NominalModel(mabi)
    half = np.array([1.0, 2.0])

    def names(settings: dict, theta: np.ndarray) -> list[tuple[str, float]]:
        spec = EffectSpec('viscous_friction', 0, mabi.joints[0], settings)
        return [
            (p['name'], p['value'])
            for p in describe_parameters(spec, theta, half[: len(theta)], model)
        ]

    assert names({}, np.array([400.0])) == [('coefficient', 400.0)]
    assert names({'exponent': 0.6}, np.array([300.0])) == [
        ('power_coefficient', 300.0),
        ('exponent', 0.6),
    ]
    assert names({'exponent': 1.4, 'linear': True}, np.array([400.0, 50.0])) == [
        ('coefficient', 400.0),
        ('power_coefficient', 50.0),
        ('exponent', 1.4),
    ]
