"""A header stamp that is no time (nanosec >= 1e9, sec < 0) is refused or reported at every door.

The replay and the predictor refuse such a stamp; the readers train uses refuse it too, naming
the topic and the sample, and inspect lists it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from id_learning.bag import (
    JOINT_STATE,
    BagWriter,
    decode_joint_state,
    header_stamp_problem,
    read_joint_states,
)
from id_learning.bag.messages import NS_PER_S, typestore
from id_learning.dataset.inspect import inspect_bag
from id_learning.errors import DatasetError

JOINTS = ('joint_1', 'joint_2')
T0_S = 1_700_000_000


def raw_joint_state(sec: int, nanosec: int) -> bytes:
    """A JointState whose header holds ``sec`` and ``nanosec`` as given (not normalised)."""
    store = typestore()
    time = store.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)
    header = store.types['std_msgs/msg/Header'](stamp=time, frame_id='')
    values = np.array([0.1, 0.2])
    msg = store.types[JOINT_STATE](header=header, name=list(JOINTS), position=values,
                                   velocity=values, effort=values)  # fmt: skip
    return bytes(store.serialize_cdr(msg, JOINT_STATE))


@given(sec=st.integers(-(2**31), 2**31 - 1), nanosec=st.integers(0, 2**32 - 1))
def test_a_stamp_is_a_time_iff_nanosec_is_below_1e9_and_sec_is_not_negative(sec, nanosec):
    problem = decode_joint_state(raw_joint_state(sec, nanosec)).stamp_problem
    assert problem == header_stamp_problem(sec, nanosec)
    assert (problem is None) == (0 <= nanosec < NS_PER_S and sec >= 0)
    if problem is not None:
        assert str(nanosec) in problem
        assert str(sec) in problem


def write_bag(path: Path, bad: int | None, n: int = 20) -> Path:
    """JointStates on /joint_states; sample ``bad`` stamped as sec - 1, nanosec 1e9 + x."""
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k in range(n):
            sec, nanosec = T0_S, k * 8_000_000
            if k == bad:
                sec, nanosec = sec - 1, nanosec + NS_PER_S  # the same instant, not normalised
            writer.write('/joint_states', T0_S * NS_PER_S + k, raw_joint_state(sec, nanosec))
    return path


def test_train_s_reader_refuses_the_stamp_naming_topic_and_sample(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bag', bad=7)
    with pytest.raises(DatasetError, match=r'/joint_states sample 7 .*invalid header stamp: '
                       r'nanosec 1056000000 is not in \[0, 1e9\)'):  # fmt: skip
        read_joint_states(bag, '/joint_states')
    assert len(read_joint_states(write_bag(tmp_path / 'ok', bad=None), '/joint_states').stamps_ns)


def test_inspect_lists_the_stamp(tmp_path: Path) -> None:
    report = inspect_bag(write_bag(tmp_path / 'bag', bad=7))
    (line,) = [p for p in report.problems if 'invalid header stamp' in p]
    assert line.startswith('/joint_states: 1 invalid header stamp(s), the first at sample 7: ')
    assert 'nanosec 1056000000 is not in [0, 1e9)' in line
    ok = inspect_bag(write_bag(tmp_path / 'ok', bad=None))
    assert not [p for p in ok.problems if 'stamp' in p]
