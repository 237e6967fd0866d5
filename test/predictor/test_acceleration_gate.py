"""Given accelerations against the velocities' own change (``predictor.acceleration_gate``).

The probe's B83: accelerations sent as zeros while the arm accelerates were served (the pair
check allows 2x the acceleration limit), 19 % of joint 1's torque limit off. Generated streams:
smooth motions with velocity noise up to five times the twins' (1e-3 rad/s), accelerations true
or differentiated from the noisy velocities as the replay builds them, pass; zeros (or any
accelerations off by more than the floor allows) while a joint accelerates fail and get no model
torque; the shipped bag's reference (as the replay sends it) passes whole.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from predictor.test_stream_properties import SteepModel

from id_learning.dataset.consistency import KinematicConsistency
from id_learning.predictor import FeedForwardPredictor, ReferenceSample, Reject
from id_learning.predictor.acceleration_gate import StreamGate, acceleration_terms

PERIOD_NS = 8_000_000
REPO = Path(__file__).resolve().parents[2]


def failures(gate: KinematicConsistency, stamps, q, v, a) -> list[int]:
    stream = StreamGate(gate)
    out = []
    for k, stamp in enumerate(stamps):
        if stream.check(int(stamp), q[k], v[k], a[k]) is not None:
            out.append(k)
        stream.push(int(stamp), q[k], v[k], a[k])
    return out


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    shares=st.lists(st.floats(0.0, 0.9), min_size=6, max_size=6),
    hz=st.floats(0.05, 1.5),
    noise=st.sampled_from([0.0, 1e-3, 5e-3]),
    derived=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_noisy_consistent_streams_pass(mabi, shares, hz, noise, derived, seed):
    w = 2 * np.pi * hz
    # Amplitudes within the velocity and acceleration limits (shares of the tighter).
    amp = np.array(shares) * np.minimum(mabi.limits.velocity / w, mabi.limits.acceleration / w**2)
    amp = np.minimum(amp, 0.9 * (mabi.limits.position_upper - mabi.limits.position_lower) / 2)
    n = 300
    stamps = 10**9 + np.arange(n) * PERIOD_NS
    t = (stamps - stamps[0])[:, None] * 1e-9
    phase = np.arange(6)
    q = amp * np.sin(w * t + phase)
    v = amp * w * np.cos(w * t + phase) + np.random.default_rng(seed).normal(0, noise, (n, 6))
    true_a = -amp * w**2 * np.sin(w * t + phase)
    a = np.gradient(v, t[:, 0], axis=0, edge_order=2) if derived else true_a
    gate = KinematicConsistency(tuple(mabi.joints), mabi.limits, 0.008)
    assert failures(gate, stamps, q, v, a) == []


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    joint=st.integers(0, 5),
    over=st.floats(1.15, 3.0),
    sign=st.sampled_from([-1.0, 1.0]),
    lie=st.sampled_from(['zeros', 'reversed', 'half']),
)
def test_accelerations_that_contradict_the_velocities_get_no_model_torque(
    mabi, joint, over, sign, lie
):
    gate = KinematicConsistency(tuple(mabi.joints), mabi.limits, 0.008)
    given_share = {'zeros': 0.0, 'reversed': -1.0, 'half': 0.5}[lie]
    # The constant acceleration a0 at which the check's ratio is ``over``: mismatch and
    # tolerance are affine in |a0| for a constant acceleration (c1 |a0| against floor + c2 |a0|).
    steps = np.full((gate.window, 1), 0.008)

    def terms(a0: float) -> tuple[float, float]:
        given_a = np.full((gate.window + 1, 6), given_share * a0)
        mismatch, tolerance, _ = acceleration_terms(
            gate, steps, np.full(6, a0 * steps.sum()), given_a
        )
        return float(mismatch[joint]), float(tolerance[joint])

    floor = terms(0.0)[1]
    c1, c2 = terms(1.0)[0], terms(1.0)[1] - floor
    if c1 <= over * c2:
        return  # no acceleration makes this lie fail by ``over``: the relative term covers it
    a0 = sign * over * floor / (c1 - over * c2)
    if abs(a0) > 1.9 * mabi.limits.acceleration[joint]:
        return  # beyond what the plausibility gate lets through
    n = 40
    stamps = 10**9 + np.arange(n) * PERIOD_NS
    t = (stamps - stamps[0]) * 1e-9
    q, v, a = np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 6))
    v0 = -0.5 * a0 * t[-1]  # through zero in the middle: within the velocity limit
    q[:, joint] = v0 * t + 0.5 * a0 * t**2
    v[:, joint] = v0 + a0 * t
    a[:, joint] = given_share * a0
    assert set(range(gate.window, n)) <= set(failures(gate, stamps, q, v, a))  # full windows
    predictor = FeedForwardPredictor(SteepModel(mabi), mabi.limits.torque,
                                     limits=mabi.limits.take(range(6)))  # fmt: skip
    results = [
        predictor.step(
            ReferenceSample(int(s), tuple(mabi.joints), q[k], v[k], a[k]), int(s) + 10**6
        )
        for k, s in enumerate(stamps)
    ]
    assert all(r.reject in (Reject.INCONSISTENT, Reject.REARMING) for r in results[gate.window :])


def test_the_shipped_bags_reference_passes_whole(mabi):
    from id_learning.dataset.inputs import InputDefinition
    from id_learning.dataset.recording import read_joint_states
    from id_learning.predictor.reference import reference_from_states

    states = read_joint_states(REPO / 'bags/default', mabi.topics.joint_states)
    names = tuple(states.names)
    assert names == tuple(mabi.joints)
    reference = reference_from_states(  # the replay's default reference (controller inputs)
        names, states.stamps_ns, states.position, states.velocity,
        period_s=mabi.ipo_period_s, inputs=InputDefinition.controller(mabi.input_smoothing_hz),
    )  # fmt: skip
    gate = KinematicConsistency.for_robot(mabi, names)
    r = reference
    assert failures(gate, r.stamps_ns, r.q, r.v, r.a) == []


def test_the_shipped_bags_recorded_reference_passes(mabi):
    """q and v as recorded (the twin's noise), a differentiated from them: 100 s of it."""
    from id_learning.dataset.recording import read_joint_states
    from id_learning.predictor.reference import reference_from_states

    states = read_joint_states(REPO / 'bags/default', mabi.topics.joint_states)
    part = slice(0, 12_500)
    r = reference_from_states(
        tuple(states.names), states.stamps_ns[part], states.position[part],
        states.velocity[part], period_s=mabi.ipo_period_s,
    )  # fmt: skip
    gate = KinematicConsistency.for_robot(mabi, tuple(states.names))
    assert failures(gate, r.stamps_ns, r.q, r.v, r.a) == []
