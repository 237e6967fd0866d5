"""Stamps that go backwards because two publishers shared a recorded topic (probe R03) are named
as two interleaved streams; a single step back is not."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.dataset.plausibility import check_stamps
from id_learning.dataset.recording import load_recording
from id_learning.errors import DatasetError

PERIOD_NS = 8_000_000
T0 = 1_767_225_600_000_000_000
INTERLEAVED = 'two interleaved streams (two publishers?)'


def _interleave(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty(a.size + b.size, dtype=np.int64)
    out[0::2], out[1::2] = a, b
    return out


@pytest.mark.parametrize('lag_s', [5.0, -5.0, -0.004])
def test_two_streams_in_turn_are_named_as_interleaved(lag_s: float) -> None:
    a = T0 + np.arange(100, dtype=np.int64) * PERIOD_NS
    stamps = _interleave(a, a + round(lag_s * 1e9) + 1)
    with pytest.raises(DatasetError, match=r'time stamp goes backwards at sample \d+') as caught:
        check_stamps(stamps, 0.008, 10.0, 'bag: /joint_states')
    assert INTERLEAVED in str(caught.value)


def test_two_streams_at_different_rates_are_named_as_interleaved() -> None:
    fast = T0 + np.arange(300, dtype=np.int64) * PERIOD_NS
    slow = T0 - 3_000_000_000 + np.arange(30, dtype=np.int64) * 10 * PERIOD_NS
    stamps = np.concatenate([fast[:50], *(np.r_[fast[50 + 10 * k : 60 + 10 * k], slow[k]] for k
                                          in range(25))])  # fmt: skip
    with pytest.raises(DatasetError, match=re.escape(INTERLEAVED)):
        check_stamps(stamps, 0.008, 10.0, 'bag: /joint_states')


@pytest.mark.parametrize(
    'stamps',
    [
        np.r_[np.arange(10), np.arange(5, 15)],  # one clock step back: one stream
        np.r_[np.arange(10), 3, np.arange(10, 20)],  # one stamp out of place
        np.r_[np.arange(10), np.arange(5, 15), np.arange(2, 30)],  # three streams
    ],
)
def test_one_step_back_or_three_streams_are_not_named_as_two(stamps: np.ndarray) -> None:
    with pytest.raises(DatasetError, match='goes backwards') as caught:
        check_stamps(T0 + stamps.astype(np.int64) * PERIOD_NS, 0.008, 10.0, 'bag')
    assert INTERLEAVED not in str(caught.value)


def test_a_bag_two_publishers_shared_is_refused_naming_two_interleaved_streams(
    tmp_path: Path, mabi: Any
) -> None:
    joints = mabi.joints
    n = 200
    t = np.arange(n) * 0.008
    q = 0.3 * np.sin(2 * np.pi * 0.2 * t)[:, None] * np.ones(len(joints))
    v = 0.3 * 2 * np.pi * 0.2 * np.cos(2 * np.pi * 0.2 * t)[:, None] * np.ones(len(joints))
    zero = np.zeros(len(joints))
    with BagWriter(tmp_path / 'shared') as writer:
        for topic in ('/joint_states', '/motor_currents'):
            writer.add_topic(topic, JOINT_STATE)
        log = T0
        for k in range(n):  # one replay, and the same bag replayed again 50 cycles later
            for sample in (k, k - 50) if k >= 50 else (k,):
                stamp = T0 + sample * PERIOD_NS
                log += PERIOD_NS // 2
                state = encode_joint_state(stamp, joints, q[sample], v[sample], zero)
                writer.write('/joint_states', log, state)
                current = encode_joint_state(stamp, joints, zero, zero, zero)
                writer.write('/motor_currents', log, current)
    with pytest.raises(DatasetError, match='goes backwards') as caught:
        load_recording(tmp_path / 'shared', mabi)
    assert INTERLEAVED in str(caught.value)
