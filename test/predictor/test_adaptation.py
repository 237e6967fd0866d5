"""Online friction adaptation: convergence, drift, and the safeguards."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from id_learning.predictor.adaptation import AdaptationConfig, FrictionAdapter

LIMIT = np.array([2000.0, 1500.0, 800.0])
VELOCITY = np.array([1.5, 1.5, 2.0])
PERIOD = 0.008


def adapter(**settings: float) -> FrictionAdapter:
    return FrictionAdapter(LIMIT, VELOCITY, PERIOD, AdaptationConfig(**settings))


def stream(theta: np.ndarray, n: int, seed: int = 0, noise: float = 2.0):
    """Velocities sweeping both directions and measured tau_u = model + theta . phi + noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * PERIOD
    v = np.stack([np.sin(0.7 * t + k) * VELOCITY[k] * 0.8 for k in range(3)], axis=1)
    model = rng.normal(0.0, 100.0, (n, 3))
    phi = np.stack([np.tanh(v / 0.01), v, np.ones_like(v)], axis=2)
    measured = model + np.einsum('njk,jk->nj', phi, theta) + noise * rng.standard_normal((n, 3))
    return v, measured, model


TRUE = np.array([[60.0, 40.0, 5.0], [45.0, 30.0, -3.0], [20.0, 10.0, 1.0]])


def test_it_converges_to_the_friction_the_model_lacks() -> None:
    fit = adapter()
    v, measured, model = stream(TRUE, 20_000)
    for k in range(len(v)):
        fit.update(v[k], measured[k], model[k])
    np.testing.assert_allclose(fit.theta, TRUE, rtol=0.05, atol=0.5)
    assert fit.counters.updates == len(v)


def test_it_follows_a_friction_that_falls_by_a_third() -> None:
    fit = adapter(time_constant_s=120.0)
    # A step every two minutes, then four time constants at the last level.
    for part, (scale, n) in enumerate(((1.0, 15_000), (0.85, 15_000), (0.7, 60_000))):
        v, measured, model = stream(TRUE * scale, n, seed=part)
        for k in range(len(v)):
            fit.update(v[k], measured[k], model[k])
    np.testing.assert_allclose(fit.theta[:, :2], 0.7 * TRUE[:, :2], rtol=0.06)


def test_spikes_are_gated_and_bad_or_stale_input_changes_nothing() -> None:
    fit = adapter()
    v, measured, model = stream(TRUE, 5000)
    for k in range(len(v)):
        fit.update(v[k], measured[k], model[k])
    before = fit.theta.copy()
    spike = measured[0] + np.array([5000.0, 0.0, 0.0])
    assert fit.update(v[0], spike, model[0])  # joints 2 and 3 learn; joint 1 is gated
    np.testing.assert_allclose(fit.theta[0], before[0])
    assert fit.counters.gated >= 1
    frozen = fit.theta.copy()
    assert not fit.update(v[1], np.full(3, np.nan), model[1])
    assert not fit.update(v[1], measured[1], model[1], stale=True)
    np.testing.assert_array_equal(fit.theta, frozen)
    assert fit.counters.frozen == 2


def test_parameters_and_covariance_stay_bounded() -> None:
    fit = adapter(gate_sigmas=1e9)
    v = np.zeros(3)
    for _ in range(20_000):  # a robot at rest: no excitation, and an absurd offset
        fit.update(v, np.full(3, 1e5), np.zeros(3))
    assert (np.abs(fit.theta) <= fit.bounds + 1e-9).all()
    np.testing.assert_allclose(fit.theta[:, 2], 0.1 * LIMIT)
    trace = np.trace(fit.covariance, axis1=1, axis2=2)
    assert (trace <= np.trace(fit._p0, axis1=1, axis2=2) * (1 + 1e-9)).all()
    assert np.isfinite(fit.covariance).all()


def test_the_state_is_saved_beside_the_artifact_never_in_it(tmp_path: Path) -> None:
    artifact = tmp_path / 'rnea_id'
    artifact.mkdir()
    (artifact / 'model.json').write_text('{}')
    fit = adapter()
    path = fit.save(artifact, ('a', 'b', 'c'))
    assert path.parent == tmp_path
    assert sorted(p.name for p in artifact.iterdir()) == ['model.json']
    state = json.loads(path.read_text())
    assert state['joints'] == ['a', 'b', 'c']
    assert np.array(state['theta']).shape == (3, 3)


@pytest.mark.parametrize('time_constant', [60.0, 600.0])
def test_the_forgetting_factor_follows_the_time_constant(time_constant: float) -> None:
    assert adapter(time_constant_s=time_constant).forgetting == pytest.approx(
        1 - PERIOD / time_constant
    )


def test_the_covariance_stays_symmetric_and_a_broken_one_starts_afresh() -> None:
    """Forgetting amplifies rounding: an unsymmetrised RLS diverges after ~10^5 updates."""
    fit = adapter()
    v, measured, model = stream(TRUE, 3000)
    for k in range(len(v)):
        fit.update(v[k], measured[k], model[k])
    np.testing.assert_array_equal(fit.covariance, np.swapaxes(fit.covariance, 1, 2))
    fit.covariance[1, 0, 0] = np.nan
    fit.update(v[0], measured[0], model[0])
    assert fit.counters.resets == 1
    assert np.isfinite(fit.covariance).all()
    np.testing.assert_allclose(fit.covariance[1], fit._p0[1])


def test_a_scale_shrunk_at_standstill_lets_motion_back_in() -> None:
    """At rest the error is noise; the model's errors in motion must not be gated for good."""
    from id_learning.errors import ConfigError

    fit = adapter(time_constant_s=20.0)
    rng = np.random.default_rng(4)
    for _ in range(20_000):  # 160 s at rest: the scale falls to the 1 N*m noise
        fit.update(np.zeros(3), rng.standard_normal(3), np.zeros(3))
    assert (fit.error_scale < 2.0).all()
    v, measured, model = stream(TRUE, 5000, noise=1.0)
    for k in range(len(v)):
        fit.update(v[k], measured[k], model[k])
    assert fit.counters.updates > 24_000  # motion is learnt from, not gated
    np.testing.assert_allclose(fit.theta[:, :2], TRUE[:, :2], rtol=0.1)
    with pytest.raises(ConfigError, match='at least 10 periods'):
        adapter(time_constant_s=0.05)


def test_a_payload_the_model_lacks_is_learnt_as_a_change_of_the_base_parameters(mabi) -> None:
    """The model: the URDF's rigid body; the arm carries 60 kg more (pinocchio with a payload)."""
    from id_learning.physics.rigid_body import RigidBodyDynamics
    from id_learning.predictor.adaptation import AdaptationLoop

    nominal = RigidBodyDynamics.from_config(mabi)
    loaded = nominal.with_payload(
        mabi.payload_frame, 60.0, np.array([0.1, 0.0, 0.05]), np.diag([0.3, 0.5, 0.5])
    )
    loop = AdaptationLoop.for_robot(
        mabi, mabi.joints, AdaptationConfig(time_constant_s=30.0), inertia=True
    )
    assert loop.inertia is not None
    rng = np.random.default_rng(2)
    n = 3000
    t = np.arange(n) * 0.008
    phase = rng.uniform(0, 2 * np.pi, 6)
    speed = rng.uniform(0.3, 0.8, 6)
    q = 0.6 * np.sin(speed * t[:, None] + phase)
    v = 0.6 * speed * np.cos(speed * t[:, None] + phase)
    a = -0.6 * speed**2 * np.sin(speed * t[:, None] + phase)
    model = nominal.rnea(q, v, a)
    truth = loaded.rnea(q, v, a)
    per_ampere = loop.torque_per_ampere
    errors = []
    for k in range(n):
        tau = loop.serve(1000 + k, (q[k], v[k], a[k]), model[k])
        errors.append(tau - truth[k])
        noisy = truth[k] + rng.normal(0.0, 5.0, 6)
        loop.measured(1000 + k, noisy / per_ampere)
    errors = np.array(errors)
    before = np.sqrt(np.mean((model - truth)[-500:] ** 2, axis=0))
    after = np.sqrt(np.mean(errors[-500:] ** 2, axis=0))
    assert (before[1:5] > 40.0).all()  # 60 kg at the flange: hundreds of N*m on axes 2 and 3
    assert (after[1:5] < 0.05 * before[1:5]).all()
    assert (after < before).all()
    assert loop.inertia.updates > 0.9 * n
    state = loop.inertia.state()
    assert len(state['change']) == len(state['base_parameters'])


def test_the_rigid_body_adapter_works_in_the_model_s_joint_order(mabi) -> None:
    from id_learning.errors import ConfigError
    from id_learning.predictor.adaptation_inertia import InertiaAdapter

    forward = InertiaAdapter(mabi, mabi.joints, 0.008, 30.0, 0.5)
    order = [5, 3, 0, 1, 4, 2]
    permuted = InertiaAdapter(mabi, tuple(mabi.joints[i] for i in order), 0.008, 30.0, 0.5)
    rng = np.random.default_rng(8)
    q, v, a = (rng.uniform(-0.5, 0.5, 6) for _ in range(3))
    base = forward.regressor(q, v, a)[:, 18:]
    moved = permuted.regressor(q[order], v[order], a[order])[:, 18:]
    np.testing.assert_allclose(moved, base[order], rtol=1e-12, atol=1e-12)
    with pytest.raises(ConfigError, match='needs every joint'):
        InertiaAdapter(mabi, mabi.joints[:5], 0.008, 30.0, 0.5)
