"""Bags that hold the same samples are never trained on together, nor scored as unseen."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.dataset.recording import Recording, load_recording, write_recording
from id_learning.errors import DatasetError
from id_learning.training import evaluate_run
from id_learning.training.datasets import (
    MIN_SHARED_SAMPLES,
    load_datasets,
    shared_samples,
    shared_stamps,
)


def _cut(recording: Recording, start: int, stop: int) -> Recording:
    rows = slice(start, stop)
    return replace(
        recording,
        stamps_ns=recording.stamps_ns[rows],
        position=recording.position[rows],
        velocity=recording.velocity[rows],
        current=None if recording.current is None else recording.current[rows],
        joint_torque=None,
        segment_starts=(0,),
    )


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.integers(0, 400), st.integers(1, 400), st.integers(0, 400), st.integers(1, 400))
def test_shared_stamps_are_exactly_the_overlap_of_two_cuts(a, length_a, b, length_b):
    stamps = 1_000 + 8 * np.arange(900, dtype=np.int64)
    q = np.random.default_rng(3).normal(size=(900, 2))
    first = ('a', stamps[a : a + length_a], q[a : a + length_a])
    second = ('b', stamps[b : b + length_b], q[b : b + length_b])

    shared = shared_stamps(first, second)

    overlap = np.arange(max(a, b), min(a + length_a, b + length_b))
    moving = overlap[overlap > a]  # the first sample of a cut has no motion before it to compare
    np.testing.assert_array_equal(shared, stamps[moving])
    # Another recording at the same stamps (twin recordings all start at one epoch) shares none.
    other = ('c', stamps[a : a + length_a], q[a : a + length_a] + 1e-9)
    assert shared_stamps(other, second).size == 0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.integers(0, 400),
    st.integers(1, 400),
    st.integers(0, 400),
    st.integers(1, 400),
    st.integers(-(10**12), 10**12),
)
def test_shared_samples_are_found_whatever_the_stamps_of_the_second(
    a, length_a, b, length_b, shift
):
    stamps = 1_000 + 8 * np.arange(900, dtype=np.int64)
    q = np.random.default_rng(3).normal(size=(900, 2))
    first = ('a', stamps[a : a + length_a], q[a : a + length_a])
    second = ('b', stamps[b : b + length_b] + shift, q[b : b + length_b])  # re-stamped cut

    in_first, in_second = shared_samples(first, second)

    overlap = np.arange(max(a, b), min(a + length_a, b + length_b))
    moving = overlap[overlap > a]
    np.testing.assert_array_equal(in_first, stamps[moving])
    np.testing.assert_array_equal(in_second, stamps[moving] + shift)


def _segments(recording: Recording, parts: list[tuple[int, int]]) -> Recording:
    """Rows [start, stop) of ``recording`` per part, one segment each, 1 s after one another."""
    period_ns = int(np.median(np.diff(recording.stamps_ns)))
    pieces = [_cut(recording, start, stop) for start, stop in parts]
    stamps, next_ns = [], int(recording.stamps_ns[0])
    for piece in pieces:
        stamps.append(next_ns + period_ns * np.arange(piece.n_samples, dtype=np.int64))
        next_ns = int(stamps[-1][-1]) + 10**9
    starts = np.cumsum([0] + [piece.n_samples for piece in pieces[:-1]])

    def joined(name: str) -> np.ndarray | None:
        arrays = [getattr(piece, name) for piece in pieces]
        return None if arrays[0] is None else np.concatenate(arrays)

    return replace(
        recording,
        stamps_ns=np.concatenate(stamps),
        position=joined('position'),
        velocity=joined('velocity'),
        current=joined('current'),
        joint_torque=None,
        segment_starts=tuple(int(k) for k in starts),
    )


def test_a_bag_whose_segments_share_samples_is_refused_naming_bag_segments_and_stamps(
    bags, mabi, tmp_path
):
    recording = load_recording(bags[0], mabi)
    n = recording.n_samples
    # Two overlapping logs imported as two segments: the end of the first is the second's start.
    bag = write_recording(
        _segments(recording, [(0, n // 2), (n // 2 - 500, n)]), tmp_path / 'ovl', mabi.topics
    )
    with pytest.raises(DatasetError) as err:
        load_datasets([bag], mabi, PreprocessConfig(), progress=False)
    found = re.fullmatch(
        r'(\S+) segment 1 of 2 and (\S+) segment 2 of 2 hold the same (\d+) samples \(stamps '
        r'(\d+) to (\d+) ns in the first, (\d+) to (\d+) ns in the second, [\d.]+ s\): the '
        r'same motion would be in the training and the test part; the bag holds them twice .*',
        str(err.value),
    )
    assert found, err.value
    assert found[1] == found[2] == str(bag)
    # The twin's quantised positions stand still now and then: the moving ones are counted.
    assert MIN_SHARED_SAMPLES <= int(found[3]) <= 500
    overlap = recording.stamps_ns[n // 2 - 500 : n // 2]
    assert overlap[0] <= int(found[4]) < int(found[5]) <= overlap[-1]
    # Segments that follow one another without an overlap hold no sample twice.
    apart = write_recording(
        _segments(recording, [(0, n // 2), (n // 2, n)]), tmp_path / 'apart', mabi.topics
    )
    assert len(load_datasets([apart], mabi, PreprocessConfig(), progress=False)) == 2


def test_a_segment_re_stamped_from_another_bag_is_refused(bags, mabi, tmp_path):
    recording = load_recording(bags[0], mabi)
    n = recording.n_samples
    # A piece of bags[0] as the second segment of another bag, at other stamps than in bags[0].
    other = load_recording(bags[1], mabi)
    piece = _segments(recording, [(n // 2, n // 2 + 2 * MIN_SHARED_SAMPLES)])
    joined = Recording(
        joints=recording.joints,
        stamps_ns=np.concatenate([other.stamps_ns, piece.stamps_ns + 10**12]),
        position=np.concatenate([other.position, piece.position]),
        velocity=np.concatenate([other.velocity, piece.velocity]),
        current=np.concatenate([other.current, piece.current]),
        segment_starts=(0, other.n_samples),
    )
    bag = write_recording(joined, tmp_path / 'mixed', mabi.topics)
    with pytest.raises(
        DatasetError,
        match=r'twin_11 and .*mixed segment 2 of 2 hold the same 1\d\d samples \(stamps \d+ to '
        r'\d+ ns in the first, \d+ to \d+ ns in the second',
    ):
        load_datasets([bags[0], bag], mabi, PreprocessConfig(), progress=False)


def test_a_bag_that_repeats_itself_is_refused_naming_both_stretches(bags, mabi, tmp_path):
    """A looped replay recorded into one bag: its test part would be a copy of training."""
    recording = load_recording(bags[0], mabi)
    n = recording.n_samples
    span = int(recording.stamps_ns[-1] - recording.stamps_ns[0]) + 8_000_000
    twice = Recording(
        joints=recording.joints,
        stamps_ns=np.concatenate([recording.stamps_ns, recording.stamps_ns + span]),
        position=np.concatenate([recording.position, recording.position]),
        velocity=np.concatenate([recording.velocity, recording.velocity]),
        current=np.concatenate([recording.current, recording.current]),
    )
    bag = write_recording(twice, tmp_path / 'twice', mabi.topics)
    with pytest.raises(DatasetError) as err:
        load_datasets([bag], mabi, PreprocessConfig(), progress=False)
    found = re.fullmatch(
        r'(\S+) holds the same (\d+) samples twice: stamps (\d+) to (\d+) ns again ([\d.]+) s '
        r'later, from (\d+) ns: the same motion would be in the training and the test part; .*',
        str(err.value),
    )
    assert found, err.value
    assert found[1] == str(bag)
    assert int(found[2]) > n // 2  # the moving samples of the whole first copy
    assert float(found[5]) == pytest.approx(span * 1e-9, abs=0.05)
    assert int(found[6]) - int(found[3]) == span
    # The same commanded motion run twice, with the sensors' own noise each time: no copy.
    again = load_recording(bags[0], mabi)
    noise = np.random.default_rng(5).normal(0.0, 1e-3, size=again.current.shape)
    rerun = replace(twice, current=np.concatenate([recording.current, again.current + noise]))
    fresh = write_recording(rerun, tmp_path / 'rerun', mabi.topics)
    assert load_datasets([fresh], mabi, PreprocessConfig(), progress=False)


@pytest.fixture(scope='module')
def cut_bag(bags, mabi, tmp_path_factory):
    """The last 30 s of the first training bag, as a bag of its own."""
    recording = load_recording(bags[0], mabi)
    n = recording.n_samples
    folder = tmp_path_factory.mktemp('cut')
    return write_recording(_cut(recording, n - 3750, n), folder / 'cut', mabi.topics)


def test_two_bags_holding_the_same_samples_are_not_trained_on_together(bags, cut_bag, mabi):
    with pytest.raises(DatasetError, match=r'cut and .*twin_11 hold the same \d+ samples') as err:
        load_datasets([cut_bag, bags[0]], mabi, PreprocessConfig(), progress=False)
    assert 'training and the test part' in str(err.value)
    # Two twin recordings share their stamps but no sample: loaded together without a word.
    assert len(load_datasets(bags, mabi, PreprocessConfig(), progress=False)) == 2


def test_a_bag_cut_from_a_training_bag_is_not_scored_as_unseen(run, cut_bag, mabi, tmp_path):
    with pytest.raises(DatasetError, match=r'hold the same \d+ samples.*counts? training'):
        evaluate_run(run.out, [cut_bag], mabi, tmp_path / 'eval', progress=False)
    assert not (tmp_path / 'eval').exists()
