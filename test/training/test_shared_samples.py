"""Bags that hold the same samples are never trained on together, nor scored as unseen."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.dataset.recording import Recording, load_recording, write_recording
from id_learning.errors import DatasetError
from id_learning.training import evaluate_run
from id_learning.training.datasets import load_datasets, shared_stamps


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
