"""Fitting a network through the label filter: its torque meets a label only after that filter.

The labels are zero-phase Butterworth low-passes of the measured torque (``Dataset.cutoff_hz``,
0.3-1.2 Hz on the MABI arm). A feed-forward model predicts the torque the drive needs *now*,
from unfiltered inputs; to compare it with a label, its torque along the recording passes the
same filter first (parallel filtering, Gautier and Khalil). Linear-in-parameters models filter
their regressor columns (``Dataset.filter_like_labels``); networks are trained here, on
contiguous windows of the training part:

- the label filter is written as its symmetric FIR: the impulse response of the forward-backward
  Butterworth (``scipy.signal.sosfiltfilt``), cut where its tail holds less than ``TAIL`` of its
  absolute mass, so that inside a recording it reproduces the label filter to a fraction of the
  label noise (0.07 N*m on the MABI arm's 0.3 Hz joints);
- a window holds ``interior`` samples whose loss counts, plus the FIR's half length on either
  side, whose inputs are read but whose labels are not; the network's torque over the window is
  convolved with the FIR (by FFT) and the interior compared with the labels;
- optionally the network is evaluated on every ``eval_stride``-th sample only, at a random phase
  per batch, and the samples in between count as zero with the others weighted by the stride:
  an unbiased estimate of the filtered torque for networks too costly to run on every sample.

Windows never cross from one recording into another. Windows of the validation part may read
the inputs (never the labels) of samples after it, as the filter's support needs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from scipy import signal

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.signals import butterworth
from id_learning.errors import DatasetError
from id_learning.models.torch_utils import to_tensor

__all__ = ['TAIL', 'FilterWindows', 'LabelFilter', 'ThroughFilterLoss', 'zero_phase_kernel']

#: Share of the zero-phase filter's absolute impulse-response mass left out by the FIR.
TAIL = 2e-4

#: (rows (B, H + W) dataset rows in time order, positions (P,) columns of rows to evaluate)
#: -> torque (B, P, n) [N*m] at those positions.
WindowPredictor = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def zero_phase_kernel(
    cutoff_hz: float, period_s: float, order: int, tail: float = TAIL
) -> np.ndarray:
    """The label filter's impulse response (2K + 1,), centred, cut where its tail is negligible.

    Applying it by convolution equals ``sosfiltfilt`` with this design away from a signal's ends.
    """
    sos = butterworth(float(cutoff_hz), float(period_s), int(order))
    length = max(64, round(4.0 / (cutoff_hz * period_s)))
    while True:
        impulse = np.zeros(2 * length + 1)
        impulse[length] = 1.0
        response = signal.sosfiltfilt(sos, impulse, padlen=0)
        magnitude = np.abs(response)
        # Mass beyond k samples from the centre, on both sides together.
        beyond = 2.0 * np.cumsum(magnitude[::-1])[::-1][length:]
        inside = np.flatnonzero(beyond <= tail * magnitude.sum())
        if inside.size and inside[0] < length // 2:
            half = int(inside[0])
            kernel: np.ndarray = response[length - half : length + half + 1]
            return kernel
        length *= 2


class LabelFilter:
    """The label filter of every joint as FIR kernels of one common half length K.

    Args:
        cutoff_hz: (n,) the labels' cut-offs [Hz].
        period_s: sample period [s].
        order: Butterworth order of each pass.
        tail: see ``zero_phase_kernel``.
    """

    def __init__(
        self, cutoff_hz: np.ndarray, period_s: float, order: int, tail: float = TAIL
    ) -> None:
        """Design the kernels (the slowest joint sets K)."""
        kernels = [zero_phase_kernel(fc, period_s, order, tail) for fc in cutoff_hz]
        self.half_length = max(len(k) // 2 for k in kernels)
        taps = np.zeros((len(kernels), 2 * self.half_length + 1))
        for j, kernel in enumerate(kernels):
            pad = self.half_length - len(kernel) // 2
            taps[j, pad : pad + len(kernel)] = kernel
        #: (n, 2K + 1) kernels, centre at K.
        self.taps = taps
        self._spectra: dict[tuple[int, str], torch.Tensor] = {}

    @classmethod
    def of(cls, dataset: Dataset, tail: float = TAIL) -> LabelFilter:
        """The filter that made a dataset's labels."""
        return cls(np.asarray(dataset.cutoff_hz), dataset.period_s, dataset.filter_order, tail)

    def _spectrum(self, size: int, device: torch.device) -> torch.Tensor:
        key = (size, str(device))
        if key not in self._spectra:
            taps = torch.as_tensor(self.taps, dtype=torch.float32, device=device)
            self._spectra[key] = torch.fft.rfft(taps, n=size)
        return self._spectra[key]

    def __call__(self, torque: torch.Tensor) -> torch.Tensor:
        """Filter windows (B, W, n) [N*m]; returns their interiors (B, W - 2K, n).

        Raises:
            ValueError: a window shorter than the kernel.
        """
        length = torque.shape[1]
        k = self.half_length
        if length <= 2 * k:
            raise ValueError(f'{length}-sample windows are too short for a {2 * k + 1}-tap FIR')
        size = 1 << math.ceil(math.log2(length + 2 * k))
        spectrum = torch.fft.rfft(torque.transpose(1, 2), n=size)
        full = torch.fft.irfft(spectrum * self._spectrum(size, torque.device), n=size)
        out: torch.Tensor = full[..., 2 * k : length].transpose(1, 2)
        return out


@dataclass(frozen=True, eq=False)
class FilterWindows:
    """Windows of one dataset part for fitting through the filter.

    Attributes:
        rows: (n_windows, H + W) dataset rows, in time order within one recording; the first H
            are history for sequence models, then the window of W = interior + 2K samples.
        mask: (n_windows, interior) whether an interior sample belongs to the part.
        history: H.
        half_length: K.
    """

    rows: np.ndarray
    mask: np.ndarray
    history: int
    half_length: int

    @property
    def interior(self) -> int:
        """Samples per window whose loss counts (where the part allows)."""
        return int(self.mask.shape[1])


def plan_windows(
    dataset: Dataset,
    in_part: np.ndarray,
    half_length: int,
    interior: int,
    history: int = 0,
) -> FilterWindows:
    """Tile a part's samples with windows (interiors overlapping by half).

    Args:
        dataset: the dataset (its recordings give the time order).
        in_part: (N,) True for the rows of the part, in dataset row order.
        half_length: K, samples read on either side of an interior.
        interior: samples per interior.
        history: samples read before the window (a sequence model's window length - 1).
    """
    span = history + interior + 2 * half_length
    step = max(1, interior // 2)
    rows, masks = [], []
    for time_rows in dataset.recording_rows():
        inside = in_part[time_rows]
        if len(time_rows) < span or not inside.any():
            continue
        first, last = np.flatnonzero(inside)[[0, -1]]
        # Interior starts (in time) such that the whole window lies in the recording.
        lowest, highest = history + half_length, len(time_rows) - interior - half_length
        start = max(first, lowest)
        while start <= max(last, lowest):
            begin = min(start, highest)
            window = time_rows[begin - history - half_length : begin + interior + half_length]
            mask = inside[begin : begin + interior]
            if mask.any():
                rows.append(window)
                masks.append(mask)
            if begin == highest:
                break
            start += step
    if not rows:
        empty = np.zeros((0, span), dtype=np.int64)
        return FilterWindows(empty, np.zeros((0, interior), bool), history, half_length)
    return FilterWindows(np.stack(rows), np.stack(masks), history, half_length)


class ThroughFilterLoss:
    """The normalised MSE between filtered network torque and the labels, over windows.

    Items for ``train_module`` are window indices (``fit_items``, ``validation_items``); the
    loss of a batch of them is ``loss(predict, items)``.

    Args:
        dataset: the dataset the windows are cut from.
        fit_rows, validation_rows: dataset rows of the two parts.
        target: (N, n) what the filtered torque must match [N*m] (the labels, or labels minus
            a fixed physics part filtered like them).
        scale: (n,) per-joint normalisation [N*m] (the study's half ranges).
        device: where the tensors live.
        interior: samples per window whose loss counts; None: twice the FIR's half length (or
            less, where the longest recording is shorter than that window).
        loss_stride: compare every loss_stride-th interior sample (the filtered torque is
            smooth far beyond this).
        eval_stride: evaluate the network on every eval_stride-th sample (see the module).
        history: samples before each window that the predictor reads (sequence models).
        seed: seeds the evaluation phase.

    Raises:
        DatasetError: a part too short for one window.
    """

    def __init__(
        self,
        dataset: Dataset,
        fit_rows: np.ndarray,
        validation_rows: np.ndarray,
        target: np.ndarray,
        *,
        scale: np.ndarray,
        device: torch.device,
        interior: int | None = None,
        loss_stride: int = 4,
        eval_stride: int = 1,
        history: int = 0,
        seed: int = 0,
    ) -> None:
        """Design the FIR and plan the windows of both parts."""
        self.filter = LabelFilter.of(dataset)
        k = self.filter.half_length
        # Twice the FIR's half length, or what the longest recording leaves beside the margins.
        longest = max(len(rows) for rows in dataset.recording_rows())
        interior = min(interior or 2 * k, longest - 2 * k - history)
        n_rows = len(dataset.tau)
        parts = {}
        for name, rows in (('fit', fit_rows), ('validation', validation_rows)):
            in_part = np.zeros(n_rows, dtype=bool)
            in_part[rows] = True
            parts[name] = plan_windows(dataset, in_part, k, max(interior, 1), history)
            if interior < 1 or not len(parts[name].rows):
                seconds = (history + 2 * k + 1) * dataset.period_s
                raise DatasetError(
                    f'{dataset.source}: the {name} part is too short to fit through the label '
                    f'filter: the {float(np.min(dataset.cutoff_hz)):g} Hz filter reads '
                    f'{k * dataset.period_s:.1f} s on either side of a sample, so the part needs '
                    'samples that far from both ends of a recording longer than '
                    f"{seconds:.0f} s; record longer or use the study's preprocessing "
                    '(--preprocessing study)'
                )
        self.n_fit = len(parts['fit'].rows)
        windows = np.concatenate([parts['fit'].rows, parts['validation'].rows])
        masks = np.concatenate([parts['fit'].mask, parts['validation'].mask])
        self.history, self.half_length = history, k
        self.loss_stride, self.eval_stride = loss_stride, eval_stride
        self.width = windows.shape[1] - history
        self.rows = torch.as_tensor(windows, device=device)
        interior = parts['fit'].interior
        picked = slice(0, interior, loss_stride)
        interior_rows = windows[:, history + k : history + k + interior][:, picked]
        self.target = to_tensor(np.asarray(target)[interior_rows], device)
        self.mask = torch.as_tensor(masks[:, picked], dtype=torch.float32, device=device)
        self.inverse_scale = to_tensor(1.0 / np.asarray(scale, dtype=float), device)
        self._generator = torch.Generator().manual_seed(seed)
        self.device = device

    @property
    def fit_items(self) -> list[torch.Tensor]:
        """The fit part's windows, as items for train_module."""
        return [torch.arange(self.n_fit, device=self.device)]

    @property
    def validation_items(self) -> list[torch.Tensor]:
        """The validation part's windows."""
        return [torch.arange(self.n_fit, len(self.rows), device=self.device)]

    def filtered(
        self, predict: WindowPredictor, items: torch.Tensor, *, phase: int | None = None
    ) -> torch.Tensor:
        """The filtered torque (B, interior / loss_stride, n) of windows ``items``.

        ``phase``: the first evaluated sample when ``eval_stride`` > 1; None draws it.
        """
        rows = self.rows[items]
        stride = self.eval_stride
        if stride == 1:
            positions = torch.arange(self.history, self.history + self.width, device=self.device)
            torque = predict(rows, positions)
        else:
            if phase is None:
                phase = int(torch.randint(stride, (1,), generator=self._generator))
            positions = torch.arange(
                self.history + phase, self.history + self.width, stride, device=self.device
            )
            sampled = predict(rows, positions)
            torque = sampled.new_zeros((len(items), self.width, sampled.shape[2]))
            torque[:, phase::stride] = sampled * stride
        return self.filter(torque)[:, :: self.loss_stride]

    def loss(self, predict: WindowPredictor, items: torch.Tensor) -> torch.Tensor:
        """Mean squared error on the normalised scale over the windows' part samples."""
        training = torch.is_grad_enabled()
        filtered = self.filtered(predict, items, phase=None if training else 0)
        error = (filtered - self.target[items]) * self.inverse_scale
        mask = self.mask[items]
        return torch.sum(error.square() * mask[..., None]) / (
            torch.sum(mask) * error.shape[2]
        ).clamp(min=1.0)
