"""Only a copy holds another recording's samples: a second run of one motion is no copy.

Two runs of one commanded motion (a twin simulated twice on one excitation, a setpoint run
twice) repeat the positions, a twin's exactly (the trajectory, quantised by the encoders), but
not the sensors' noise: their currents and measured velocities differ. A copy keeps every value,
whether it keeps its stamps (a cut) or is re-stamped.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.bag.distinct import (
    MIN_SHARED_SAMPLES,
    refuse_shared_samples,
    shared_samples,
)
from id_learning.errors import DatasetError

N = 600
PERIOD_NS = 8_000_000
T0_NS = 1_767_225_600_000_000_000
ENCODER_STEP = 2 * np.pi / (4096 * 100)  # rad at the joint: 4096 counts, gear 100


def _run(
    noise_seed: int, *, start_ns: int = T0_NS
) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """One run of the same commanded motion: exact quantised positions, noisy currents."""
    t = np.arange(N) * PERIOD_NS * 1e-9
    q = 0.5 * np.sin(2 * np.pi * np.array([0.2, 0.3])[None, :] * t[:, None])
    q = np.round(q / ENCODER_STEP) * ENCODER_STEP
    current = 2.0 * np.cos(2 * np.pi * 0.2 * t)[:, None] + np.random.default_rng(
        noise_seed
    ).normal(0.0, 0.05, (N, 2))
    stamps = start_ns + PERIOD_NS * np.arange(N, dtype=np.int64)
    return f'run {noise_seed}', stamps, q, current


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    st.integers(0, 10**6),
    st.integers(0, 10**6),
    st.sampled_from([0, PERIOD_NS, 3_600 * 10**9]),
)
def test_two_runs_of_one_commanded_motion_are_no_copies(
    first_seed: int, second_seed: int, apart_ns: int
) -> None:
    if first_seed == second_seed:
        second_seed += 1
    first, second = _run(first_seed), _run(second_seed, start_ns=T0_NS + apart_ns)
    np.testing.assert_array_equal(first[2], second[2])  # the positions repeat exactly
    assert shared_samples(first, second)[0].size == 0
    refuse_shared_samples([first, second], 'why')  # nothing refused


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.integers(0, N - MIN_SHARED_SAMPLES - 1), st.integers(-(10**15), 10**15))
def test_a_copy_is_found_at_its_stamps_or_re_stamped(cut: int, shift: int) -> None:
    name, stamps, q, current = _run(7)
    moving = np.flatnonzero(np.any(q[1:] != q[:-1], axis=1)) + 1
    copy = ('copy', stamps[cut:] + shift, q[cut:], current[cut:])

    in_first, in_copy = shared_samples((name, stamps, q, current), copy)

    expected = stamps[moving[moving >= cut]]
    np.testing.assert_array_equal(in_first, expected)
    np.testing.assert_array_equal(in_copy, expected + shift)
    with pytest.raises(
        DatasetError, match=rf'run 7 and copy hold the same {expected.size} samples'
    ):
        refuse_shared_samples([(name, stamps, q, current), copy], 'why')


def test_without_noisy_values_on_both_sides_positions_alone_decide() -> None:
    """The fallback: two runs of one exact trajectory then look like copies."""
    first, second = _run(1), _run(2)
    positions_only = (second[0], second[1], second[2])
    assert shared_samples(first, positions_only)[0].size > MIN_SHARED_SAMPLES
    assert shared_samples(first, (*positions_only, None))[0].size > MIN_SHARED_SAMPLES
    assert shared_samples(first, second)[0].size == 0
