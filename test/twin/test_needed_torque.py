"""The torque a drive needs on a twin bag: the label torque without its delay, on the plan."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from support import quick_preprocess, twin_config

from id_learning.training.datasets import load_datasets
from id_learning.twin import (
    GROUND_TRUTH_ARRAYS,
    GROUND_TRUTH_JSON,
    simulate,
    write_twin_output,
)
from id_learning.twin.needed_torque import needed_torque
from id_learning.twin.simulate import TWIN_CONFIG_COPY, TwinConfig, TwinResult

PERIOD_S = 0.008  # the MABI's IPO period
#: A delay of whole IPO periods: the label at sample k + 2 is the needed torque at sample k.
DELAY_SAMPLES = 2


def _twin(delay_s: float, **overrides: object) -> TwinConfig:
    """A 30 s default twin whose label lags the motion by ``delay_s`` (0: no delay)."""
    effects = copy.deepcopy(twin_config(30.0).raw['effects'])
    effects['signal_delay'] = {'enabled': delay_s > 0, 'delay_s': delay_s}
    return twin_config(30.0, effects=effects, **overrides)


def _bag(config: TwinConfig, folder: Path) -> tuple[Path, TwinResult]:
    result = simulate(config)
    return write_twin_output(result, config, folder / 'twin'), result


def _ground_truth_only(bag: Path, folder: Path) -> Path:
    """A folder holding a copy of the bag's ground truth, without its twin config."""
    folder.mkdir()
    for name in (GROUND_TRUTH_JSON, GROUND_TRUTH_ARRAYS):
        (folder / name).write_bytes((bag / name).read_bytes())
    return folder


def _float32_spacing(x: np.ndarray) -> np.ndarray:
    """The distance to the next float32 of each value (the stored torque's resolution)."""
    return np.spacing(np.abs(x).astype(np.float32)).astype(float)


@pytest.fixture(scope='module')
def undelayed(mabi, tmp_path_factory):
    """A twin bag without the signal delay, its simulation and its dataset."""
    bag, result = _bag(_twin(0.0), tmp_path_factory.mktemp('undelayed'))
    [dataset] = load_datasets([bag], mabi, quick_preprocess(), progress=False)
    return bag, result, dataset


def test_without_a_delay_the_needed_torque_is_the_stored_label_torque(undelayed) -> None:
    bag, result, dataset = undelayed
    needed, why = needed_torque(bag, dataset)
    assert why == ''
    assert needed is not None
    rows = np.searchsorted(result.recording.stamps_ns, dataset.stamps_ns)
    assert len(rows) > 3000  # the precondition: most of the 26 s run survived
    with np.load(bag / GROUND_TRUTH_ARRAYS) as arrays:
        stored = arrays['tau_u_clean'][rows].astype(float)
    assert np.all(np.abs(needed.torque - stored) <= _float32_spacing(stored))
    np.testing.assert_allclose(needed.torque, result.tau_u_clean[rows], rtol=0, atol=1e-9)


def test_the_reference_is_the_plan_in_the_encoders_coordinates(mabi, undelayed) -> None:
    bag, result, dataset = undelayed
    needed, _ = needed_torque(bag, dataset)
    assert needed is not None
    rows = np.searchsorted(result.recording.stamps_ns, dataset.stamps_ns)
    offset = np.asarray(result.parameters['effects']['joint_offset']['offset'])
    assert np.any(offset != 0)
    np.testing.assert_array_equal(needed.reference.q, result.q_true[rows] - offset)
    np.testing.assert_array_equal(needed.reference.v, result.v_true[rows])
    np.testing.assert_array_equal(needed.reference.a, result.a_true[rows])
    # The recorded positions are the same, quantised by the encoder (2**20 counts per turn).
    step = 2 * np.pi / (2**20 * mabi.drives.gear_ratio)
    assert np.all(np.abs(needed.reference.q - result.recording.position[rows]) <= step)


def test_with_a_delay_the_needed_torque_leads_the_label_by_the_delay(mabi, tmp_path) -> None:
    bag, result = _bag(_twin(DELAY_SAMPLES * PERIOD_S), tmp_path)
    [dataset] = load_datasets([bag], mabi, quick_preprocess(), progress=False)
    needed, why = needed_torque(bag, dataset)
    assert why == ''
    assert needed is not None
    rows = np.searchsorted(result.recording.stamps_ns, dataset.stamps_ns)
    later = rows + DELAY_SAMPLES
    keep = later < len(result.tau_u_clean)
    assert keep.sum() > 3000
    label_later = result.tau_u_clean[later[keep]]
    # The same motion, its time reached by two roundings ((k + 2) T - 2 T and k T): equal
    # to far below the float32 resolution of the stored label.
    np.testing.assert_allclose(needed.torque[keep], label_later, rtol=0, atol=1e-6)
    # ... and not the label at the same sample, which lags it.
    lag = np.sqrt(np.mean((needed.torque - result.tau_u_clean[rows]) ** 2, axis=0))
    assert np.all(lag > 0.05)


def test_a_joint_target_needs_the_joint_torque_at_the_sample_time(mabi, tmp_path) -> None:
    config = _twin(
        DELAY_SAMPLES * PERIOD_S,
        joint_torque_sensors=True,
        measurement={'joint_torque_noise_std': 0.0},
    )
    bag, result = _bag(config, tmp_path)
    [dataset] = load_datasets([bag], mabi, quick_preprocess(target='joint'), progress=False)
    needed, why = needed_torque(bag, dataset)
    assert why == ''
    assert needed is not None
    rows = np.searchsorted(result.recording.stamps_ns, dataset.stamps_ns)
    assert result.recording.joint_torque is not None
    # A noise-free torque sensor sees the motion at the sample time, as the drive needs it.
    np.testing.assert_allclose(
        needed.torque, result.recording.joint_torque[rows], rtol=1e-12, atol=1e-9
    )


def test_a_bag_without_ground_truth_has_no_needed_torque(undelayed, tmp_path) -> None:
    _, _, dataset = undelayed
    assert needed_torque(tmp_path, dataset) == (None, '')


def test_a_bag_without_its_twin_config_says_so(undelayed, tmp_path) -> None:
    bag, _, dataset = undelayed
    copy_ = _ground_truth_only(bag, tmp_path / 'copy')
    needed, why = needed_torque(copy_, dataset)
    assert needed is None
    assert f'{TWIN_CONFIG_COPY}: missing' in why


def test_a_twin_config_changed_since_the_simulation_is_refused(undelayed, tmp_path) -> None:
    bag, _, dataset = undelayed
    copy_ = _ground_truth_only(bag, tmp_path / 'copy')
    raw = yaml.safe_load((bag / TWIN_CONFIG_COPY).read_text(encoding='utf-8'))
    raw['robot'] = str((bag / raw['robot']).resolve())
    raw['effects']['torque_offset']['offset'][0] += 1.0  # N*m
    (copy_ / TWIN_CONFIG_COPY).write_text(yaml.safe_dump(raw), encoding='utf-8')
    needed, why = needed_torque(copy_, dataset)
    assert needed is None
    assert 'joint_1' in why
    assert 'changed since the bag was simulated' in why


def test_stamps_of_another_simulation_are_refused(undelayed) -> None:
    bag, _, dataset = undelayed
    shifted = replace(dataset, stamps_ns=dataset.stamps_ns + 1)
    needed, why = needed_torque(bag, shifted)
    assert needed is None
    assert 'not those of the simulation' in why
