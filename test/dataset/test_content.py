"""Signal content (``dataset.content``): invariants over generated signals.

A constant or zero label is refused for any joint; a moving joint with noise is never called
still, a still one always is; clipped sines are found saturated at their clip level, unclipped
(noisy, quantised, several harmonics) never.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from id_learning.dataset.content import (
    STILL_SPAN_RAD,
    check_content,
    label_findings,
    motion_findings,
    saturated_levels,
)
from id_learning.errors import DatasetError

PERIOD_S = 0.008


def joint_names(n: int) -> tuple[str, ...]:
    return tuple(f'joint_{k + 1}' for k in range(n))


def moving(n_samples: int, n_joints: int, seed: int) -> np.ndarray:
    """(N, n) sines of 0.3 rad and more, each joint its own frequency and phase."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * PERIOD_S
    freq = rng.uniform(0.5, 2.0, n_joints)
    return (0.3 + rng.uniform(0, 1, n_joints)) * np.sin(
        2 * np.pi * freq * t[:, None] + rng.uniform(0, 2 * np.pi, n_joints)
    )


def quantised(x: np.ndarray, step: float) -> np.ndarray:
    return x if step == 0 else np.round(x / step) * step


@given(
    n_joints=st.integers(1, 7),
    data=st.data(),
    value=st.one_of(st.just(0.0), st.just(-0.0), st.floats(-500, 500, allow_nan=False)),
    n_samples=st.integers(2, 400),
    seed=st.integers(0, 2**16),
)
def test_any_constant_or_zero_label_is_refused_naming_the_joint(
    n_joints, data, value, n_samples, seed
):
    joint = data.draw(st.integers(0, n_joints - 1))
    names = joint_names(n_joints)
    label = np.random.default_rng(seed).normal(0.0, 2.0, (n_samples, n_joints))
    label[:, joint] = value
    with pytest.raises(DatasetError) as caught:
        check_content(moving(n_samples, n_joints, seed), label, names, where='bag')
    text = str(caught.value)
    assert text.startswith('bag: ')
    if value == 0:
        assert f'{names[joint]}: motor current is exactly 0 A in every sample' in text
        assert 'no torque was recorded' in text
    else:
        assert f'{names[joint]}: motor current is {value:.6g} A in every sample' in text


@given(n_joints=st.integers(2, 7), n_samples=st.integers(1, 300))
def test_every_label_exactly_zero_is_one_refusal_naming_every_joint(n_joints, n_samples):
    names = joint_names(n_joints)
    with pytest.raises(DatasetError) as caught:
        check_content(
            moving(max(n_samples, 2), n_joints, 0),
            np.zeros((max(n_samples, 2), n_joints)),
            names,
            where='bag',
            quantity='joint torque',
            unit='N*m',
        )
    text = str(caught.value)
    assert (
        f'joint torque is exactly 0 N*m in every sample of every joint ({", ".join(names)}' in text
    )
    assert text.count('exactly 0') == 1


@given(
    amplitude=st.floats(0.005, 3.0),
    frequency=st.floats(0.1, 5.0),
    noise_share=st.floats(0.0, 0.1),
    step_share=st.sampled_from([0.0, 1e-4, 1e-3, 1e-2]),
    n_samples=st.integers(100, 4000),
    seed=st.integers(0, 2**16),
)
def test_a_moving_joint_with_noise_is_never_called_still(
    amplitude, frequency, noise_share, step_share, n_samples, seed
):
    rng = np.random.default_rng(seed)
    n_samples = max(n_samples, math.ceil(1.2 / (frequency * PERIOD_S)))  # a period at least
    t = np.arange(n_samples) * PERIOD_S
    q = amplitude * np.sin(2 * np.pi * frequency * t + rng.uniform(0, 2 * np.pi))
    q = quantised(q + rng.normal(0, noise_share * amplitude, n_samples), step_share * amplitude)
    offset = rng.uniform(-2, 2)
    assert motion_findings((q + offset)[:, None], ('joint_1',)) == []


@given(
    n_joints=st.integers(1, 7),
    data=st.data(),
    noise=st.floats(0.0, 1e-3),
    step=st.sampled_from([0.0, 1e-6, 1e-5]),
    n_samples=st.integers(50, 4000),
    seed=st.integers(0, 2**16),
)
def test_a_still_joint_is_warned_and_no_joint_moving_is_refused(
    n_joints, data, noise, step, n_samples, seed
):
    rng = np.random.default_rng(seed)
    still = data.draw(st.lists(st.integers(0, n_joints - 1), min_size=1, unique=True))
    q = moving(n_samples + 200, n_joints, seed)[200:]  # every sine spans more than a period
    for j in still:
        q[:, j] = quantised(rng.uniform(-1, 1) + rng.normal(0, noise, n_samples), step)
    names = joint_names(n_joints)
    findings = motion_findings(q, names, duration_s=n_samples * PERIOD_S)
    if len(still) == n_joints:
        assert [f.kind for f in findings] == ['no_motion']
        assert findings[0].text.startswith('no joint moves: nothing to identify')
        with pytest.raises(DatasetError, match='no joint moves: nothing to identify'):
            check_content(q, None, names, where='bag')
        return
    assert sorted(f.joint for f in findings) == sorted(names[j] for j in still)
    assert all(f.kind == 'still' and not f.refuses for f in findings)
    for finding in findings:
        assert finding.text.startswith(f'{finding.joint} does not move: its position spans ')
        assert 'friction and inertia cannot be identified' in finding.text
    assert len(check_content(q, None, names, where='bag', warn=False)) == len(still)


def harmonics(rng: np.random.Generator, n_samples: int, amplitude: float) -> np.ndarray:
    """1 to 3 harmonics of a random base frequency, their peak near ``amplitude``."""
    t = np.arange(n_samples) * PERIOD_S
    base = rng.uniform(0.2, 3.0)
    weights = rng.uniform(0.2, 1.0, rng.integers(1, 4))
    x = sum(
        w * np.sin(2 * np.pi * base * (k + 1) * t + rng.uniform(0, 2 * np.pi))
        for k, w in enumerate(weights)
    )
    return amplitude * x / np.max(np.abs(x))


@given(
    amplitude=st.floats(0.1, 50.0),
    clip=st.floats(0.3, 0.95),
    sides=st.sampled_from(['both', 'upper', 'lower']),
    noise_share=st.floats(0.0, 0.02),
    step_share=st.sampled_from([0.0, 1e-3, 5e-3, 1e-2]),
    frequency=st.floats(0.1, 1.0),
    periods=st.floats(2.0, 20.0),
    seed=st.integers(0, 2**16),
)
def test_clipped_sines_are_found_saturated_at_their_clip_level(
    amplitude, clip, sides, noise_share, step_share, frequency, periods, seed
):
    rng = np.random.default_rng(seed)
    n_samples = math.ceil(periods / (frequency * PERIOD_S))
    t = np.arange(n_samples) * PERIOD_S
    x = amplitude * np.sin(2 * np.pi * frequency * t + rng.uniform(0, 2 * np.pi))
    x = quantised(x + rng.normal(0, noise_share * amplitude, n_samples), step_share * amplitude)
    level = clip * amplitude
    low, high = (-level, level)
    if sides == 'upper':
        low = -np.inf
    elif sides == 'lower':
        high = np.inf
    clipped = np.clip(x, low, high)
    found = dict(saturated_levels(clipped))
    expected = {'both': {level, -level}, 'upper': {level}, 'lower': {-level}}[sides]
    assert set(found) == expected
    findings = label_findings(clipped[:, None], ('joint_2',))
    assert [f.kind for f in findings] == ['saturated']
    assert findings[0].text.startswith(
        f'joint_2: motor current sits at {sorted(expected)[-1]:.6g} A'
    )
    assert not findings[0].refuses


@given(
    amplitude=st.floats(0.1, 50.0),
    offset_share=st.floats(-0.5, 0.5),
    noise_share=st.floats(0.0, 0.05),
    step_share=st.sampled_from([0.0, 1e-3, 5e-3, 1e-2]),
    n_samples=st.integers(50, 5000),
    seed=st.integers(0, 2**16),
)
def test_unclipped_signals_are_never_found_saturated(
    amplitude, offset_share, noise_share, step_share, n_samples, seed
):
    rng = np.random.default_rng(seed)
    x = harmonics(rng, n_samples, amplitude) + offset_share * amplitude
    x = quantised(x + rng.normal(0, noise_share * amplitude, n_samples), step_share * amplitude)
    assert saturated_levels(x) == []
    assert label_findings(x[:, None], ('joint_1',)) == []


def test_an_extreme_of_zero_is_no_saturation():
    x = np.maximum(np.sin(np.linspace(0, 20 * np.pi, 2000)), 0.0)  # a drive off half the time
    assert saturated_levels(x) == []


def test_still_span_is_far_below_any_excitation():
    # 20 counts of a 17-bit joint-side encoder; the twins' excitations span radians.
    assert 2 * np.pi / 2**17 * 15 < STILL_SPAN_RAD < 0.01
