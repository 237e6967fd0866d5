"""Spectra of torque errors, and the label-noise floor as a spectrum.

An RMSE says how large an error is, not where it lies in frequency; a controls engineer needs the
second: a slow error (an offset, a gravity or friction bias) is what a feed-forward must get
right, while content near the label filter's cut-off may be noise the labels carry. The spectra
here are one-sided power spectral densities [unit^2/Hz] whose integral over frequency is the
signal's mean square, so they read in the same units as the RMSE tables (squared, per Hz).

The labels are low-passed by a zero-phase Butterworth filter (power gain |H(f)|^4), so their
noise, white before the filter, has the density S0 |H(f)|^4 after it; ``filtered_noise_density``
draws that shape for a given RMS, the label-noise floor no model can go below.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import signal

from id_learning.dataset.signals import butterworth
from id_learning.dataset.statistics import filter_power_integral

__all__ = ['filtered_noise_density', 'power_spectral_density']


def _welch_segments(length: int, segment: int) -> int:
    """How many half-overlapping Welch segments a stretch of ``length`` samples holds."""
    return 0 if length < segment else (length - segment) // (segment // 2) + 1


def power_spectral_density(
    x: np.ndarray,
    period_s: float,
    *,
    stretches: Sequence[tuple[int, int]] | None = None,
    segment_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of each column of x, Welch-averaged over stretches.

    Hann-windowed, half-overlapping segments; no detrending, so a constant error (a bias) stays
    in the lowest bins and the bins summed times their width give the mean square (the squared
    RMSE of an error), not the variance.

    Args:
        x: (N, n) samples at a uniform period [unit].
        period_s: the sample period [s].
        stretches: [start, stop) rows of x, each contiguous in time (rows of two stretches are
            not neighbours); default: all of x, one stretch.
        segment_s: Welch segment length [s] (sets the resolution 1 / segment_s); default and
            at most the longest stretch. Stretches shorter than a segment are left out.

    Returns:
        freqs (F,) [Hz] from 0 to the Nyquist frequency, and the density (F, n) [unit^2/Hz].

    Raises:
        ValueError: fewer than 8 samples in the longest stretch.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    stretches = list(stretches) if stretches is not None else [(0, len(x))]
    longest = max((b - a for a, b in stretches), default=0)
    if longest < 8:
        raise ValueError(
            f'a spectrum needs a stretch of at least 8 samples, the longest has {longest}'
        )
    segment = longest if segment_s is None else min(longest, max(8, round(segment_s / period_s)))
    total = np.zeros((segment // 2 + 1, x.shape[1]))
    weight = 0
    freqs = np.fft.rfftfreq(segment, period_s)
    for a, b in stretches:
        count = _welch_segments(b - a, segment)
        if count == 0:
            continue
        freqs, psd = signal.welch(
            x[a:b],
            fs=1.0 / period_s,
            window='hann',
            nperseg=segment,
            noverlap=segment // 2,
            detrend=False,
            scaling='density',
            axis=0,
        )
        total += count * psd
        weight += count
    return freqs, total / weight


def filtered_noise_density(
    rms: np.ndarray,
    cutoff_hz: np.ndarray,
    period_s: float,
    order: int,
    freqs: np.ndarray,
) -> np.ndarray:
    """(F, n) density of white noise after the zero-phase label filter, at RMS ``rms`` (n,).

    S(f) = rms^2 |H(f)|^4 / integral_0^{f_s/2} |H|^4 df, so that it integrates to rms^2: the
    label-noise floor (an RMS the report gives) drawn as the spectrum it has.

    Args:
        rms: (n,) RMS of the filtered noise per joint [unit].
        cutoff_hz: (n,) the label filter's cut-offs [Hz].
        period_s: the sample period [s].
        order: the Butterworth order of each filter pass.
        freqs: (F,) frequencies [Hz] at or below the Nyquist frequency.
    """
    rms = np.asarray(rms, dtype=float)
    out = np.empty((len(freqs), len(rms)))
    for j, (level, cutoff) in enumerate(zip(rms, cutoff_hz, strict=True)):
        sos = butterworth(float(cutoff), period_s, order)
        _, h = signal.sosfreqz(sos, worN=np.asarray(freqs, dtype=float), fs=1.0 / period_s)
        gain = np.abs(h) ** 4
        out[:, j] = level**2 * gain / filter_power_integral(float(cutoff), period_s, order)
    return out
