"""Noise level, effective sample size and the tests the diagnosis decides with.

Filtered data are strongly correlated: a zero-phase Butterworth low-pass at f_c keeps roughly
2 f_c independent values per second, not the sampling rate. For white noise of variance sigma^2
at sampling rate f_s through the zero-phase filter (power gain |H(f)|^4),

    sigma_f^2 = sigma^2 * (2 / f_s) * integral_0^{f_s / 2} |H(f)|^4 df,
    tau       = sum_k rho_k = sigma^2 / sigma_f^2 = f_s / (2 * integral |H|^4 df)  [samples],

so N filtered samples carry n_eff = N / tau independent ones (the integral is the filter's
equivalent noise bandwidth, ~ f_c). The raw label's white-noise level comes from its
high-frequency content, where the smooth robot motion has no power.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal, stats

__all__ = [
    'NoiseEstimate',
    'effective_sample_size',
    'estimate_noise',
    'f_test',
    'filter_correlation_samples',
    'filter_power_integral',
    'first_canonical_correlation',
    'integrated_autocorrelation',
]


def filter_power_integral(cutoff_hz: float, period_s: float, order: int) -> float:
    """Integral of |H(f)|^4 over [0, f_s / 2] [Hz] for the zero-phase Butterworth low-pass."""
    fs = 1.0 / period_s
    sos = signal.butter(order, cutoff_hz, btype='low', fs=fs, output='sos')
    # The response falls as f^(-4 order) above f_c; a fine grid up to 20 f_c holds the integral.
    top = min(0.5 * fs, 20.0 * cutoff_hz)
    freqs = np.linspace(0.0, top, 8193)
    _, h = signal.sosfreqz(sos, worN=freqs, fs=fs)
    return float(np.trapezoid(np.abs(h) ** 4, freqs))


def filter_correlation_samples(cutoff_hz: float, period_s: float, order: int) -> float:
    """Integrated autocorrelation time tau [samples] of white noise after the zero-phase filter."""
    fs = 1.0 / period_s
    return max(1.0, fs / (2.0 * filter_power_integral(cutoff_hz, period_s, order)))


@dataclass(frozen=True)
class NoiseEstimate:
    """The label's noise, estimated from its high-frequency content, per joint.

    Attributes:
        raw_std_nm: (n,) white-noise standard deviation of the unfiltered label [N*m].
        filtered_std_nm: (n,) what remains of it after the zero-phase low-pass [N*m].
        correlation_samples: (n,) integrated autocorrelation time of the filtered noise
            [samples]; N samples hold N / tau independent ones.
        band_hz: (low, high) frequencies the white level was read between, over all joints
            [Hz].
    """

    raw_std_nm: np.ndarray
    filtered_std_nm: np.ndarray
    correlation_samples: np.ndarray
    band_hz: tuple[float, float]


def estimate_noise(
    tau_raw: np.ndarray, cutoff_hz: np.ndarray, period_s: float, order: int
) -> NoiseEstimate:
    """Estimate the filtered label's noise level from the raw label's high-frequency floor.

    The median of a Welch spectrum over a band well above the cut-offs (>= 10 f_c and >= f_s / 10,
    up to 0.45 f_s) is the white-noise floor; spectral lines (cogging, vibration) barely move a
    median. The floor times the filter's power integral is the filtered noise variance.

    Args:
        tau_raw: (N, n) unfiltered label torque [N*m].
        cutoff_hz: (n,) per-joint cut-offs [Hz].
        period_s: sample period [s].
        order: Butterworth order of each filter pass.

    Returns:
        The per-joint noise estimate.
    """
    tau_raw = np.asarray(tau_raw, dtype=float)
    fs = 1.0 / period_s
    n_samples, n = tau_raw.shape
    segment = int(min(512, max(64, n_samples // 8)))
    freqs, psd = signal.welch(tau_raw, fs=fs, nperseg=segment, axis=0, detrend='linear')
    raw, filtered, tau = np.empty(n), np.empty(n), np.empty(n)
    lows, highs = [], []
    for j in range(n):
        low = max(10.0 * float(cutoff_hz[j]), 0.1 * fs)
        high = 0.45 * fs
        band = (freqs >= low) & (freqs <= high)
        if band.sum() < 3:  # a very high cut-off: use the top fifth of the spectrum
            band = freqs >= 0.8 * freqs[-1]
        # The band actually read (a high cut-off leaves the nominal one empty or inverted).
        lows.append(float(freqs[band][0]))
        highs.append(float(freqs[band][-1]))
        floor = float(np.median(psd[band, j]))  # one-sided density [N^2 m^2 / Hz]
        raw[j] = math.sqrt(floor * fs / 2.0)
        filtered[j] = math.sqrt(floor * filter_power_integral(cutoff_hz[j], period_s, order))
        tau[j] = filter_correlation_samples(float(cutoff_hz[j]), period_s, order)
    return NoiseEstimate(raw, filtered, tau, (min(lows), max(highs)))


def integrated_autocorrelation(x: np.ndarray) -> float:
    """Integrated autocorrelation time 1 + 2 sum_k rho_k [samples] of a 1-D series.

    Geyer's initial positive sequence: sums of neighbouring autocorrelation pairs are added while
    they stay positive, which truncates the noisy tail without a hand-picked window.
    """
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    n_samples = len(x)
    if n_samples < 4 or not np.any(x):
        return 1.0
    size = 1 << math.ceil(math.log2(2 * n_samples))
    spectrum = np.fft.rfft(x, size)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), size)[:n_samples] / n_samples
    rho = acov / acov[0]
    total = -1.0  # Geyer: tau = -1 + 2 * sum of pair sums Gamma_m = rho_2m + rho_2m+1
    for m in range(n_samples // 2):
        pair = rho[2 * m] + rho[2 * m + 1]
        if pair <= 0.0:
            break
        total += 2.0 * pair
    return max(1.0, total)


def effective_sample_size(x: np.ndarray) -> float:
    """Number of independent samples N / tau a correlated 1-D series is worth."""
    x = np.asarray(x, dtype=float)
    return len(x) / integrated_autocorrelation(x)


def f_test(
    rss_small: float,
    rss_large: float,
    extra_parameters: float,
    n_effective: float,
    p_large: float,
) -> tuple[float, float]:
    """F statistic and p-value of adding ``extra_parameters`` columns, with effective samples.

    Both residual sums must already be in effective-sample units (each joint's squared residual
    divided by its noise variance and its correlation time). Parameter counts may be effective
    ones (a group under a prior), hence floats.

    Returns:
        (F, p-value); (0, 1) when the larger model gains nothing or no degrees of freedom remain.
    """
    dof = n_effective - p_large
    if extra_parameters <= 0 or dof <= 1.0 or rss_large <= 0.0:
        return 0.0, 1.0
    gain = max(rss_small - rss_large, 0.0)
    statistic = (gain / extra_parameters) / (rss_large / dof)
    return float(statistic), float(stats.f.sf(statistic, extra_parameters, dof))


def first_canonical_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Largest canonical correlation between the column spaces of a (m, p) and b (m, q).

    1 means some combination of a's columns is also a combination of b's: on these data the two
    groups can produce the same signal. Columns are not centred (a constant is a regressor too).
    """
    a = np.asarray(a, dtype=float).reshape(len(a), -1)
    b = np.asarray(b, dtype=float).reshape(len(b), -1)

    def basis(x: np.ndarray) -> np.ndarray:
        u, s, _ = np.linalg.svd(x, full_matrices=False)
        if not s.size or s[0] <= 0:
            return u[:, :0]
        return u[:, s > 1e-10 * s[0]]

    qa, qb = basis(a), basis(b)
    if not qa.shape[1] or not qb.shape[1]:
        return 0.0
    return float(min(1.0, np.linalg.svd(qa.T @ qb, compute_uv=False)[0]))
