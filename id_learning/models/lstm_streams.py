"""Online LSTM prediction: one sample in, its torque out, as ``LstmModel.predict`` gives it.

Holds ``LstmStreams``, the streaming form of a fitted ``NormalisedLstm`` that the online
predictor runs sample by sample (``LstmModel.sequence_predictor``): T windows in flight, numpy
and torch products on float32 or float64 copies of the weights.
"""

from __future__ import annotations

import numpy as np
import torch

from id_learning.models.network_common import NormalisedLstm
from id_learning.models.torch_utils import float64_array

__all__ = ['LstmStreams']


class LstmStreams:
    """The LSTM's online prediction, one sample per call, in float32 or float64.

    Gives what ``LstmModel.predict`` gives for a run, sample by sample: the torque of a sample
    is the LSTM run from a zero state over the window of the last T samples, and the first
    window after ``reset`` is padded with the run's first sample. Instead of recomputing each
    window (T sequential steps of one state), T windows are kept in flight: window k starts from
    zero at sample k and ends at sample k + T - 1, so each new sample advances T states at once,
    each layer's products over all of them together. The arithmetic of each window is the same
    as a recomputation; only the summation order of the products may differ. The products and
    the sigmoids run through torch on numpy arrays (its GEMM takes ~50 us here
    against ~90 us for numpy's OpenBLAS); the rest is numpy. Inputs and outputs are float64.

    Attributes:
        sequence_length: T, samples per window.
    """

    def __init__(
        self,
        network: NormalisedLstm,
        sequence_length: int,
        dtype: type[np.floating] = np.float64,
    ) -> None:
        """Copy the weights (in ``dtype``) and start empty."""
        lstm = network.lstm
        hidden, layers = lstm.hidden_size, lstm.num_layers
        # Gates reordered from torch's (i, f, g, o) to (i, f, o, g): the sigmoids side by side.
        order = np.r_[0 : 2 * hidden, 3 * hidden : 4 * hidden, 2 * hidden : 3 * hidden]

        def weight_t(name: str) -> np.ndarray:
            return float64_array(getattr(lstm, name))[order].T.astype(dtype)

        def bias(layer: int) -> np.ndarray:
            both: np.ndarray = float64_array(getattr(lstm, f'bias_ih_l{layer}')) + float64_array(
                getattr(lstm, f'bias_hh_l{layer}')
            )
            return both[order].astype(dtype)

        # Layer 0's input projection of one sample (numpy); per layer b and W_hh^T (the part
        # ``prepare`` computes ahead), and W_ih^T of the layers above the first.
        self._input_weight_t = np.ascontiguousarray(weight_t('weight_ih_l0'))
        self._biases = [torch.from_numpy(bias(layer)) for layer in range(layers)]
        self._recurrent = [
            torch.from_numpy(np.ascontiguousarray(weight_t(f'weight_hh_l{layer}')))
            for layer in range(layers)
        ]
        self._upward = [
            torch.from_numpy(np.ascontiguousarray(weight_t(f'weight_ih_l{layer}')))
            for layer in range(1, layers)
        ]
        self._head_t = np.ascontiguousarray(float64_array(network.head.weight).T)
        self._head_bias = float64_array(network.head.bias)
        self._input_centre = float64_array(network.input_centre)
        self._input_half = float64_array(network.input_half)
        self._output_centre = float64_array(network.output_centre)
        self._output_half = float64_array(network.output_half)
        self.sequence_length = sequence_length
        self._hidden = hidden
        # The windows in flight, one row each, layer l in columns l * hidden ... (l + 1) * hidden
        # (so that [h_below, h] of a layer is one slice); row _oldest ends at the next sample.
        self._dtype = dtype
        self._h = np.zeros((sequence_length, layers * hidden), dtype=dtype)
        self._c = np.zeros_like(self._h)
        self._gates = np.empty((sequence_length, 4 * hidden), dtype=dtype)
        # Per layer, b + h W_hh^T of every window, computed ahead by ``prepare``.
        self._ahead = np.empty((layers, sequence_length, 4 * hidden), dtype=dtype)
        self._is_prepared = False
        self._oldest = 0
        self._is_empty = True

    def reset(self) -> None:
        """Start a new run: the next sample is padded as a run's first."""
        self._is_empty = True
        self._is_prepared = False

    def prepare(self) -> None:
        """Compute what the next step needs of the current state alone, ahead of the sample.

        Each layer's gates are b + x W_ih^T + h W_hh^T; the recurrent part h W_hh^T of every
        window is known before the next sample arrives, so calling this after a torque has
        been published (the predictor does) takes two thirds of the products off the path from
        sample to torque. ``push`` calls it itself when it was not called.
        """
        if self._is_empty or self._is_prepared:
            return
        self._recur(self._h, self._ahead)
        self._is_prepared = True

    def push(self, row: np.ndarray) -> np.ndarray:
        """Torque (n,) [N*m] at a new sample, row (3n,) = [q, v, a] in physical units."""
        z = ((np.asarray(row, dtype=float) - self._input_centre) / self._input_half).astype(
            self._dtype
        )
        if self._is_empty:
            self._fill(z)
            self._is_empty = False
        else:
            self.prepare()
            self._step(z, self._h, self._c, self._gates, self._ahead)
        self._is_prepared = False
        oldest = self._oldest
        out = self._h[oldest, -self._hidden :].astype(float) @ self._head_t + self._head_bias
        # The oldest window is complete; its row starts a new one (from zero) at the next sample.
        self._h[oldest] = 0.0
        self._c[oldest] = 0.0
        self._oldest = (oldest + 1) % self.sequence_length
        tau: np.ndarray = out * self._output_half + self._output_centre
        return tau

    def _recur(self, h: np.ndarray, ahead: np.ndarray) -> None:
        """ahead[l] = b_l + h_l W_hh_l^T for every row of h (rows, layers * hidden)."""
        n = self._hidden
        h_t, ahead_t = torch.from_numpy(h), torch.from_numpy(ahead)
        for layer, (weight, bias) in enumerate(zip(self._recurrent, self._biases, strict=True)):
            torch.addmm(bias, h_t[:, layer * n : (layer + 1) * n], weight, out=ahead_t[layer])

    def _step(
        self, z: np.ndarray, h: np.ndarray, c: np.ndarray, gates: np.ndarray, ahead: np.ndarray
    ) -> None:
        """One LSTM step of every row of h, c in place, from ``_recur``'s parts; input z (3n,)."""
        n = self._hidden
        gates_t, h_t = torch.from_numpy(gates), torch.from_numpy(h)
        for layer in range(len(self._recurrent)):
            columns = slice(layer * n, (layer + 1) * n)
            if layer == 0:
                np.add(ahead[0], z @ self._input_weight_t, out=gates)
            else:
                below = h_t[:, (layer - 1) * n : layer * n]
                ahead_t = torch.from_numpy(ahead[layer])
                torch.addmm(ahead_t, below, self._upward[layer - 1], out=gates_t)
            self._cell_update(gates, c[:, columns], h[:, columns])

    def _cell_update(self, gates: np.ndarray, c_layer: np.ndarray, h_layer: np.ndarray) -> None:
        """In place: c = f c + i g, h = o tanh(c), from the pre-activations (i, f, o, g)."""
        n = self._hidden
        torch.from_numpy(gates)[:, : 3 * n].sigmoid_()
        cell = gates[:, 3 * n :]
        np.tanh(cell, out=cell)
        c_layer *= gates[:, n : 2 * n]
        c_layer += gates[:, :n] * cell
        np.multiply(gates[:, 2 * n : 3 * n], np.tanh(c_layer), out=h_layer)

    def _fill(self, z: np.ndarray) -> None:
        """States after a padded start: the window i-th oldest has seen T - i copies of z."""
        length = self.sequence_length
        h = np.zeros((1, self._h.shape[1]), dtype=self._dtype)
        c = np.zeros_like(h)
        gates = np.empty((1, self._gates.shape[1]), dtype=self._dtype)
        ahead = np.empty((self._ahead.shape[0], 1, self._ahead.shape[2]), dtype=self._dtype)
        for steps in range(1, length + 1):
            self._recur(h, ahead)
            self._step(z, h, c, gates, ahead)
            row = (self._oldest + length - steps) % length
            self._h[row] = h[0]
            self._c[row] = c[0]
