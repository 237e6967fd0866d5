"""Effective sample size, noise level and the diagnosis' tests, on processes with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from id_learning.dataset.preprocess import lowpass
from id_learning.dataset.statistics import (
    effective_sample_size,
    estimate_noise,
    f_test,
    filter_correlation_samples,
    first_canonical_correlation,
    integrated_autocorrelation,
)

PERIOD_S = 0.008


def ar1(phi: float, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = noise[0] / np.sqrt(1 - phi**2)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + noise[k]
    return x


@pytest.mark.parametrize('phi', [0.0, 0.5, 0.9, 0.98])
def test_effective_sample_size_of_an_ar1_process_matches_its_closed_form(phi):
    n = 200_000
    x = ar1(phi, n, seed=7)
    expected_tau = (1 + phi) / (1 - phi)  # sum of rho_k = phi^|k| over all lags
    assert integrated_autocorrelation(x) == pytest.approx(expected_tau, rel=0.1)
    assert effective_sample_size(x) == pytest.approx(n / expected_tau, rel=0.1)


def test_filtered_white_noise_has_the_filters_correlation_time_and_level():
    rng = np.random.default_rng(3)
    cutoff = np.array([0.3, 1.2])
    sigma = np.array([30.0, 5.0])
    white = rng.standard_normal((120_000, 2)) * sigma
    filtered = lowpass(white, cutoff, PERIOD_S, 4)[2000:-2000]  # without the filter's edges
    estimate = estimate_noise(white, cutoff, PERIOD_S, 4)
    for j in range(2):
        tau = filter_correlation_samples(cutoff[j], PERIOD_S, 4)
        assert estimate.correlation_samples[j] == pytest.approx(tau)
        assert integrated_autocorrelation(filtered[:, j]) == pytest.approx(tau, rel=0.2)
        assert estimate.raw_std_nm[j] == pytest.approx(sigma[j], rel=0.05)
        assert estimate.filtered_std_nm[j] == pytest.approx(np.std(filtered[:, j]), rel=0.1)
    # the slower filter keeps fewer independent samples
    assert estimate.correlation_samples[0] > 3 * estimate.correlation_samples[1]


def test_noise_estimate_ignores_a_smooth_signal_below_the_cut_off():
    rng = np.random.default_rng(4)
    t = np.arange(100_000) * PERIOD_S
    smooth = 500.0 * np.sin(2 * np.pi * 0.1 * t) + 200.0 * np.sin(2 * np.pi * 0.27 * t)
    label = (smooth + 2.0 * rng.standard_normal(t.size))[:, None]
    estimate = estimate_noise(label, np.array([0.5]), PERIOD_S, 4)
    assert estimate.raw_std_nm[0] == pytest.approx(2.0, rel=0.05)


def test_f_test_finds_a_real_gain_and_not_a_null_one():
    statistic, p_value = f_test(rss_small=200.0, rss_large=100.0, extra_parameters=1,
                                n_effective=100.0, p_large=2)  # fmt: skip
    assert statistic == pytest.approx(98.0)
    assert p_value < 1e-10
    assert f_test(100.0, 100.0, 1, 100.0, 2) == (0.0, 1.0)
    assert f_test(100.0, 99.0, 0, 100.0, 2) == (0.0, 1.0)


def test_canonical_correlation_is_one_for_spanned_columns_and_zero_for_orthogonal_ones():
    rng = np.random.default_rng(5)
    a = rng.standard_normal((500, 2))
    b = np.column_stack([a @ [1.0, -2.0], rng.standard_normal(500)])
    assert first_canonical_correlation(a, b) == pytest.approx(1.0)
    q, _ = np.linalg.qr(rng.standard_normal((500, 4)))
    assert first_canonical_correlation(q[:, :2], q[:, 2:]) == pytest.approx(0.0, abs=1e-12)


def test_a_100_hz_log_with_a_high_cut_off_reads_the_noise_in_an_ordered_band():
    """10 f_c lies above 0.45 f_s here: the top of the spectrum is read, and reported as such
    (a real 100 Hz log printed "noise band 50-45 Hz")."""
    rng = np.random.default_rng(5)
    period = 0.01
    white = 3.0 * rng.standard_normal((60_000, 2))
    estimate = estimate_noise(white, np.array([0.5, 5.0]), period, 4)
    low, high = estimate.band_hz
    assert 0.0 < low < high <= 50.0
    assert estimate.raw_std_nm == pytest.approx([3.0, 3.0], rel=0.05)
