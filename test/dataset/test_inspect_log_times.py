"""Log times that never advance (a recorder under use_sim_time without /clock) are a problem.

Such a bag shows start 1970 and duration 0; its header stamps are fine, so nothing else in the
report notices. inspect says what is wrong and why it matters.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.dataset.inspect import inspect_bag, render_report

JOINTS = ('joint_1', 'joint_2')
T0_NS = 1_767_225_600_000_000_000


def write_bag(path: Path, log_times: list[int]) -> Path:
    """One message per log time on each of two topics, header stamps 8 ms apart."""
    empty = np.zeros(0)
    with BagWriter(path) as writer:
        for topic in ('/joint_states', '/motor_currents'):
            writer.add_topic(topic, JOINT_STATE)
        for k, log_ns in enumerate(log_times):
            stamp = T0_NS + k * 8_000_000
            q = np.array([0.001 * k, 0.002 * k])
            writer.write('/joint_states', log_ns, encode_joint_state(stamp, JOINTS, q, q, empty))
            writer.write(
                '/motor_currents', log_ns, encode_joint_state(stamp, JOINTS, empty, empty, q)
            )
    return path


def log_time_lines(bag: Path) -> list[str]:
    return [p for p in inspect_bag(bag).problems if p.startswith('log times:')]


@settings(max_examples=15)
@given(
    n=st.integers(1, 40),
    at=st.sampled_from([0, T0_NS]),
    step=st.sampled_from([0, 1, 8_000_000]),
)
def test_log_times_that_never_advance_are_a_problem(
    tmp_path_factory: pytest.TempPathFactory, n: int, at: int, step: int
) -> None:
    bag = write_bag(tmp_path_factory.mktemp('logs') / 'bag', [at + k * step for k in range(n)])
    lines = log_time_lines(bag)
    if step:  # they advance: nothing to say
        assert lines == []
        return
    (line,) = lines  # two topics: even one sample each is two messages at one time
    assert line.startswith(f'log times: all {2 * n} messages carry the same log time {at} ns')
    assert "the recorder's clock stood still (use_sim_time without a /clock" in line


def test_the_report_shows_it_under_problems(tmp_path: Path) -> None:
    text = render_report(inspect_bag(write_bag(tmp_path / 'bag', [0] * 5)))
    assert 'problems  1' in text
    assert '1970-01-01T00:00:00.000000Z): the recorder' in text
