"""Error spectra against closed forms: a sine's line, flat white noise, the filter's floor."""

from __future__ import annotations

import numpy as np
import pytest

from id_learning.dataset.signals import lowpass
from id_learning.evaluation.spectra import filtered_noise_density, power_spectral_density

PERIOD_S = 0.008  # the IPO period: 125 Hz
FS = 1.0 / PERIOD_S


def test_a_sine_is_one_line_at_its_frequency_holding_its_mean_square():
    t = np.arange(0.0, 200.0, PERIOD_S)
    amplitude, f0 = 3.0, 1.25  # 1.25 Hz lies on a bin of 20 s segments (0.05 Hz apart)
    x = amplitude * np.sin(2 * np.pi * f0 * t + 0.3)
    freqs, psd = power_spectral_density(x[:, None], PERIOD_S, segment_s=20.0)
    assert freqs[1] == pytest.approx(0.05)
    assert freqs[np.argmax(psd[:, 0])] == pytest.approx(f0)
    # The line holds A^2 / 2 (Hann's main lobe spans the bin and one either side).
    df = freqs[1] - freqs[0]
    near = np.abs(freqs - f0) <= 1.5 * df
    assert np.sum(psd[near, 0]) * df == pytest.approx(amplitude**2 / 2, rel=1e-3)
    # Far from the line there is nothing: Hann's leakage falls fast.
    assert np.max(psd[np.abs(freqs - f0) > 1.0, 0]) < 1e-6 * np.max(psd)


def test_white_noise_is_flat_at_its_variance_spread_over_the_band():
    rng = np.random.default_rng(3)
    sigma = np.array([0.5, 2.0])
    x = rng.standard_normal((400_000, 2)) * sigma
    freqs, psd = power_spectral_density(x, PERIOD_S, segment_s=4.0)
    level = 2 * sigma**2 / FS  # one-sided: sigma^2 over [0, fs / 2]
    inside = (freqs > 1.0) & (freqs < FS / 2 - 1.0)
    # Flat: the low and the high half of the band agree, and both sit at the level.
    low, high = inside & (freqs < FS / 4), inside & (freqs >= FS / 4)
    np.testing.assert_allclose(psd[low].mean(axis=0), level, rtol=0.02)
    np.testing.assert_allclose(psd[high].mean(axis=0), level, rtol=0.02)
    # Each bin scatters about the level by 1 / sqrt(segments) only (about 770 of them).
    assert np.all(np.abs(psd[inside] / level - 1) < 0.25)
    # And the integral is the variance (Parseval), the squared RMSE an error of it would have.
    np.testing.assert_allclose(np.trapezoid(psd, freqs, axis=0), sigma**2, rtol=0.02)


def test_stretches_are_averaged_by_their_segments_and_a_bias_is_kept():
    rng = np.random.default_rng(4)
    x = rng.standard_normal((30_000, 1)) + 0.7  # an offset error: a bias
    whole = power_spectral_density(x, PERIOD_S, segment_s=8.0)[1]
    # The same data cut into two stretches and a short one (left out, shorter than a segment).
    parts = power_spectral_density(
        x, PERIOD_S, stretches=[(0, 12_000), (12_000, 29_900), (29_900, 30_000)], segment_s=8.0
    )
    freqs, split = parts
    np.testing.assert_allclose(split.mean(), whole.mean(), rtol=0.05)
    # Nothing is detrended: the bins sum to the mean square (1 + 0.49), the bias at 0 Hz.
    assert np.sum(split[:, 0]) * freqs[1] == pytest.approx(1.49, rel=0.05)
    assert np.argmax(split[:, 0]) == 0


def test_a_stretch_too_short_for_a_spectrum_is_refused():
    with pytest.raises(ValueError, match='at least 8 samples'):
        power_spectral_density(np.zeros((20, 1)), PERIOD_S, stretches=[(0, 5), (5, 10)])


def test_the_floor_density_is_the_spectrum_of_white_noise_through_the_label_filter():
    rng = np.random.default_rng(5)
    cutoff = np.array([0.5, 2.0])
    noise = lowpass(rng.standard_normal((300_000, 2)), cutoff, PERIOD_S, order=4)
    rms = np.sqrt(np.mean(noise**2, axis=0))
    freqs, measured = power_spectral_density(noise, PERIOD_S, segment_s=40.0)
    drawn = filtered_noise_density(rms, cutoff, PERIOD_S, 4, freqs)
    # It integrates to the floor's RMS squared, and it is the measured shape below the cut-off.
    np.testing.assert_allclose(np.trapezoid(drawn, freqs, axis=0), rms**2, rtol=0.01)
    for j, fc in enumerate(cutoff):
        band = (freqs > 0.1 * fc) & (freqs < 0.8 * fc)
        np.testing.assert_allclose(measured[band, j].mean(), drawn[band, j].mean(), rtol=0.1)
        # Two cut-offs up it has fallen by the filter's |H|^4 (order 4: 16 decades per decade).
        assert drawn[np.searchsorted(freqs, 2 * fc), j] < 1e-3 * drawn[1, j]
