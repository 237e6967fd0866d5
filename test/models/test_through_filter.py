"""Fitting through the label filter: the FIR form of the label filter, windows and the loss."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from scipy import signal
from support import quick_preprocess

from id_learning.dataset.preprocess import prepare_dataset
from id_learning.errors import DatasetError
from id_learning.models.data import TrainingData
from id_learning.models.through_filter import (
    LabelFilter,
    ThroughFilterLoss,
    plan_windows,
    zero_phase_kernel,
)
from id_learning.training import combine_datasets


def raw_signal() -> np.ndarray:
    """A random walk with steps (friction flips) on top: what labels look like before filtering."""
    rng = np.random.default_rng(0)
    steps = 100.0 * np.sign(np.sin(np.arange(20_000) / 300.0))
    return np.cumsum(rng.normal(size=20_000)) + steps


@pytest.mark.parametrize(
    ('cutoff_hz', 'period_s'), [(0.3, 0.008), (1.2, 0.008), (2.0, 0.008), (2.0, 0.001)]
)
def test_the_fir_equals_scipys_zero_phase_filter_away_from_the_ends(cutoff_hz, period_s):
    x = raw_signal()
    kernel = zero_phase_kernel(cutoff_hz, period_s, 4)
    half = len(kernel) // 2
    sos = signal.butter(4, cutoff_hz, fs=1 / period_s, output='sos')

    fir = np.convolve(x, kernel, mode='valid')
    reference = signal.sosfiltfilt(sos, x)[half:-half]

    assert len(kernel) % 2 == 1
    np.testing.assert_allclose(kernel, kernel[::-1], atol=1e-15)  # zero phase: symmetric
    assert np.max(np.abs(fir - reference)) < 1e-3 * np.max(np.abs(x))


def test_the_torch_filter_matches_scipy_and_passes_gradients_as_its_adjoint():
    cutoff = np.array([0.3, 1.2])
    label_filter = LabelFilter(cutoff, 0.008, 4)
    k = label_filter.half_length
    x = np.stack([raw_signal(), raw_signal()[::-1]], axis=1)[:8000]
    p = torch.tensor(x[None], dtype=torch.float64, requires_grad=True)

    y = label_filter(p.float())

    reference = np.stack(
        [
            signal.sosfiltfilt(signal.butter(4, fc, fs=125, output='sos'), x[:, j])
            for j, fc in enumerate(cutoff)
        ],
        axis=1,
    )[k:-k]
    np.testing.assert_allclose(y[0].detach().numpy(), reference, atol=2e-3 * np.abs(x).max())
    weights = np.random.default_rng(1).normal(size=y.shape[1:])
    (y * torch.tensor(weights, dtype=torch.float32)).sum().backward()
    # d sum(w * (h conv p)) / dp = h correlated with w; h is symmetric: a full convolution.
    expected = np.stack(
        [np.convolve(weights[:, j], label_filter.taps[j], mode='full') for j in range(2)], axis=1
    )
    assert p.grad is not None
    np.testing.assert_allclose(p.grad[0].numpy(), expected, atol=1e-5)


@pytest.fixture(scope='module')
def data(short_twin, mabi):
    _, result = short_twin
    return TrainingData(prepare_dataset(result.recording, mabi, quick_preprocess()), mabi)


def label_source(dataset):
    """A 'model' that returns the unfiltered labels of the rows asked for."""
    tau_raw = torch.as_tensor(dataset.tau_raw, dtype=torch.float32)

    def predict(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
        return tau_raw[rows[:, positions]]

    return predict


def loss_of(data, **settings) -> ThroughFilterLoss:
    return ThroughFilterLoss(
        data.dataset,
        data.fit_rows,
        data.validation_rows,
        data.dataset.tau,
        scale=data.dataset.target_scaler.scale(),
        device=torch.device('cpu'),
        **settings,
    )


def test_the_unfiltered_labels_through_the_filter_meet_the_labels(data):
    loss = loss_of(data)
    predict = label_source(data.dataset)

    def zeros(rows: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
        return torch.zeros((*rows[:, positions].shape, 6))

    with torch.no_grad():
        for items in (loss.fit_items[0], loss.validation_items[0]):
            assert float(loss.loss(predict, items)) < 1e-8
            assert float(loss.loss(zeros, items)) > 0.01


def test_evaluating_every_kth_sample_is_unbiased_over_the_phases(data):
    full = loss_of(data)
    strided = loss_of(data, eval_stride=4)
    predict = label_source(data.dataset)
    items = full.fit_items[0][:2]

    with torch.no_grad():
        exact = full.filtered(predict, items)
        phases = [strided.filtered(predict, items, phase=phase) for phase in range(4)]

    np.testing.assert_allclose(
        torch.stack(phases).mean(dim=0).numpy(), exact.numpy(), atol=1e-3, rtol=1e-5
    )
    assert not torch.allclose(phases[0], exact)  # one phase alone is an estimate


def test_windows_stay_inside_one_recording_and_cover_the_part(short_twin, mabi):
    _, result = short_twin
    first = prepare_dataset(result.recording, mabi, quick_preprocess())
    combined = combine_datasets([first, replace(first, source='second')])
    label_filter = LabelFilter.of(combined)
    k = label_filter.half_length
    in_part = np.zeros(len(combined.tau), dtype=bool)
    in_part[: combined.n_train] = True  # both training parts

    windows = plan_windows(combined, in_part, k, interior=300, history=5)

    recordings = combined.recording_rows()
    covered = np.zeros_like(in_part)
    for rows, mask in zip(windows.rows, windows.mask, strict=True):
        owners = [r for r in recordings if np.isin(rows, r).all()]
        assert len(owners) == 1  # inside one recording
        order = owners[0]
        start = int(np.flatnonzero(order == rows[0])[0])
        np.testing.assert_array_equal(rows, order[start : start + len(rows)])  # in time order
        interior = rows[5 + k : 5 + k + 300]
        np.testing.assert_array_equal(mask, in_part[interior])
        covered[interior[mask]] = True
    # Every part sample far enough from its recording's ends has a window.
    for order in recordings:
        reachable = order[5 + k : len(order) - k]
        assert covered[reachable[in_part[reachable]]].all()


def test_a_part_too_short_for_the_filter_is_refused_naming_the_way_out(short_twin, mabi):
    _, result = short_twin
    data = TrainingData(prepare_dataset(result.recording, mabi), mabi)  # 0.3 Hz, 26 s
    with pytest.raises(DatasetError, match=r'validation part is too short.*--preprocessing study'):
        loss_of(data)
