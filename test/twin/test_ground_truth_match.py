"""A twin's ground truth is used only for its own recording; otherwise ignored, saying why.

The floor figures compare models with the noise-free torque, so a ground truth of another
recording (copied beside a bag, cut short, shifted) would give impossible figures. The matcher
proves it belongs: every stamp is there, ground_truth.json describes the same arrays, and the
labels differ from it by sensor noise alone.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import twin_config

from id_learning.dataset.preprocess import Dataset, PreprocessConfig, prepare_dataset
from id_learning.twin import GROUND_TRUTH_ARRAYS, GROUND_TRUTH_JSON, simulate, write_twin_output
from id_learning.twin.ground_truth import NOISE_ALLOWANCE, read_noise_free_torque


@pytest.fixture(scope='module')
def twins(mabi):
    """Two 26 s twin runs of one robot with different seeds, and the first one's dataset."""
    runs = [simulate(twin_config(30.0, seed=seed)) for seed in (21, 22)]
    return runs, prepare_dataset(runs[0].recording, mabi)


def _write(folder: Path, stamps: np.ndarray, motor: np.ndarray, info: dict | None) -> Path:
    """ground_truth.npz (and .json unless ``info`` is None) in ``folder``, as the twin writes."""
    folder.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(folder / GROUND_TRUTH_ARRAYS, stamps_ns=stamps,
                        tau_u_clean=motor.astype(np.float32),
                        tau_joint_clean=motor.astype(np.float32))  # fmt: skip
    if info is not None:
        (folder / GROUND_TRUTH_JSON).write_text(json.dumps(info), encoding='utf-8')
    return folder


def test_its_own_ground_truth_is_used(twins, tmp_path: Path) -> None:
    (own, _), dataset = twins
    folder = _write(tmp_path, own.recording.stamps_ns, own.tau_u_clean, own.parameters)
    torque, why = read_noise_free_torque(folder, dataset)
    assert why == ''
    assert torque is not None
    np.testing.assert_allclose(torque, own.tau_u_clean, rtol=1e-6, atol=1e-3)


def test_the_last_part_of_a_run_keeps_its_ground_truth(twins, mabi, tmp_path: Path) -> None:
    """A bag of a run's last samples states its own RMS, and so its ground truth is used."""
    (own, _), _ = twins
    part = own.take(slice(len(own.tau_u_clean) // 2, None))
    rms = np.sqrt(np.mean(part.tau_u_clean**2, axis=0))
    np.testing.assert_allclose(part.parameters['tau_u_clean_rms_nm'], rms)
    assert part.parameters['excitation'] == own.parameters['excitation']
    assert len(part.recording.stamps_ns) == len(part.q_true) == len(part.tau_u_clean)
    folder = write_twin_output(part, twin_config(30.0, seed=21), tmp_path / 'part')
    torque, why = read_noise_free_torque(folder, prepare_dataset(part.recording, mabi))
    assert why == ''
    assert torque is not None


def test_an_old_ground_truth_without_json_is_still_judged(twins, tmp_path: Path) -> None:
    (own, other), dataset = twins
    folder = _write(tmp_path / 'own', own.recording.stamps_ns, own.tau_u_clean, None)
    assert read_noise_free_torque(folder, dataset)[1] == ''
    folder = _write(tmp_path / 'other', own.recording.stamps_ns, other.tau_u_clean, None)
    torque, why = read_noise_free_torque(folder, dataset)
    assert torque is None
    assert 'ground_truth.npz does not belong to this recording, or its labels are computed' in why
    assert 'the labels differ' in why


def test_another_simulations_arrays_beside_its_json_are_refused(twins, tmp_path: Path) -> None:
    """The tester's case: same start time, so the same stamps; the arrays of another seed."""
    (own, other), dataset = twins
    folder = _write(tmp_path, own.recording.stamps_ns, other.tau_u_clean, own.parameters)
    torque, why = read_noise_free_torque(folder, dataset)
    assert torque is None
    assert str(folder / GROUND_TRUTH_ARRAYS) in why
    assert 'two files are of different simulations' in why
    assert 'no label-noise floor' in why


def test_another_simulations_pair_of_files_is_refused(twins, tmp_path: Path) -> None:
    (own, other), dataset = twins
    folder = _write(tmp_path, own.recording.stamps_ns, other.tau_u_clean, other.parameters)
    torque, why = read_noise_free_torque(folder, dataset)
    assert torque is None
    assert 'the labels differ from its noise-free torque' in why
    assert 'another simulation or another motion' in why


def test_a_json_without_arrays_says_so(twins, tmp_path: Path) -> None:
    (own, _), dataset = twins
    (tmp_path / GROUND_TRUTH_JSON).write_text(json.dumps(own.parameters), encoding='utf-8')
    torque, why = read_noise_free_torque(tmp_path, dataset)
    assert torque is None
    assert why.startswith(f'{tmp_path / GROUND_TRUTH_JSON}: has no ground_truth.npz')
    assert read_noise_free_torque(tmp_path / 'absent', dataset) == (None, '')


@settings(max_examples=25)
@given(
    cut=st.tuples(st.integers(0, 3250), st.integers(1, 3251)),
    shift_ns=st.integers(-50_000_000, 50_000_000),
)
def test_a_ground_truth_lacking_a_stamp_is_refused(
    twins, tmp_path_factory: pytest.TempPathFactory, cut, shift_ns
) -> None:
    """Any cut or shift that loses one of the recording's stamps is refused, naming the first."""
    (own, _), dataset = twins
    stamps = own.recording.stamps_ns
    start, stop = min(cut), max(cut)
    kept = slice(start, max(stop, start + 1))
    moved = stamps[kept] + shift_ns
    folder = _write(tmp_path_factory.mktemp('cut'), moved, own.tau_u_clean[kept], None)
    torque, why = read_noise_free_torque(folder, dataset)
    lost = np.setdiff1d(stamps, moved)
    if lost.size == 0:
        assert why == ''
        return
    assert torque is None
    first = int(np.flatnonzero(~np.isin(stamps, moved))[0])
    lacks = f'lacks {lost.size} of the {len(stamps)} sample stamps (the first at sample {first},'
    assert lacks in why


@settings(max_examples=30)
@given(
    joint=st.integers(0, 5),
    times_noise=st.floats(0.0, 30.0),
    frequency_hz=st.floats(0.0, 20.0),
)
def test_a_label_off_beyond_the_sensor_noise_is_refused(
    twins,
    tmp_path_factory: pytest.TempPathFactory,
    joint: int,
    times_noise: float,
    frequency_hz: float,
) -> None:
    """The labels are the truth plus noise: a truth off by k times the noise is used iff k is
    small, whatever the shape of the difference (an offset, a slow or a fast wave)."""
    (own, _), dataset = twins
    noise = np.asarray(own.parameters['noise']['current_noise_std_as_tau_u_nm'])
    t = (own.recording.stamps_ns - own.recording.stamps_ns[0]) * 1e-9
    wave = np.sqrt(2.0) * np.sin(2 * np.pi * frequency_hz * t + 0.3) if frequency_hz else 1.0
    edited = own.tau_u_clean.copy()
    edited[:, joint] += times_noise * noise[joint] * wave
    info = {k: v for k, v in own.parameters.items() if k != 'tau_u_clean_rms_nm'}
    folder = _write(tmp_path_factory.mktemp('off'), own.recording.stamps_ns, edited, info)
    torque, why = read_noise_free_torque(folder, dataset)
    # noise and offset add in quadrature: off = noise * sqrt(1 + k^2) against 2 x noise
    if times_noise < 1.0:
        assert why == ''
    elif times_noise > 2.5:
        assert torque is None
        assert f'RMS on {dataset.joints[joint]}' in why
    assert NOISE_ALLOWANCE == 2.0  # the bounds above are derived from it


def test_joint_target_is_judged_against_its_sensor(mabi, tmp_path: Path) -> None:
    config = twin_config(30.0, seed=23, joint_torque_sensors=True)
    run = simulate(config)
    dataset = prepare_dataset(run.recording, mabi, PreprocessConfig(target='joint'))
    bag = write_twin_output(run, config, tmp_path / 'bag')
    assert read_noise_free_torque(bag, dataset)[1] == ''
    swapped = _joint_truth_reversed(bag, tmp_path / 'reversed')
    torque, why = read_noise_free_torque(swapped, dataset)
    assert torque is None
    assert 'the labels differ' in why


def _joint_truth_reversed(bag: Path, out: Path) -> Path:
    """A copy of the ground truth whose joint torque runs backwards (same stamps, other motion)."""
    out.mkdir()
    shutil.copy(bag / GROUND_TRUTH_JSON, out / GROUND_TRUTH_JSON)
    with np.load(bag / GROUND_TRUTH_ARRAYS) as arrays:
        data = dict(arrays)
    data['tau_joint_clean'] = data['tau_joint_clean'][::-1]
    np.savez(out / GROUND_TRUTH_ARRAYS, **data)
    return out


def test_columns_follow_the_json_joint_names(twins, tmp_path: Path) -> None:
    """A robot config listing the joints in another order gets the columns in its order."""
    (own, _), dataset = twins
    order = [5, 4, 3, 2, 1, 0]
    flipped: Dataset = replace(
        dataset,
        joints=tuple(dataset.joints[k] for k in order),
        tau_raw=dataset.tau_raw[:, order],
        cutoff_hz=dataset.cutoff_hz[order],
    )
    folder = _write(tmp_path, own.recording.stamps_ns, own.tau_u_clean, own.parameters)
    torque, why = read_noise_free_torque(folder, flipped)
    assert why == ''
    assert torque is not None
    np.testing.assert_allclose(torque, own.tau_u_clean[:, order], rtol=1e-6, atol=1e-3)


def test_labels_scaled_by_the_drive_constants_blame_the_config(twins, tmp_path: Path) -> None:
    """The stamps and the JSON match but the labels are a multiple of the truth (gear ratio 1):
    the message points at the robot config's drive constants and names each joint's factor."""
    (own, _), dataset = twins
    folder = _write(tmp_path, own.recording.stamps_ns, own.tau_u_clean, own.parameters)
    scaled = replace(dataset, tau_raw=np.asarray(dataset.tau_raw) * 0.01)
    torque, why = read_noise_free_torque(folder, scaled)
    assert torque is None
    assert 'holds every stamp of this recording' in why
    assert 'gear_ratio x torque_constant x current' in why
    factors = why.split('multiple of the truth: ')[1].split(';')[0].split(', ')
    assert [name for name, _ in (f.split() for f in factors)] == list(dataset.joints)
    assert all(abs(float(f.split()[1]) - 0.01) < 5e-4 for f in factors)
    assert 'another simulation or another motion' not in why
