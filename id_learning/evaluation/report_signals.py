"""The report's figures of signals: torque overlays in time, and error spectra in frequency.

What a controls engineer looks at beside the RMSE tables: each model's torque against the label
on a window where the motion is richest (does it follow the shape, where does it lag or miss a
friction flip?), and the spectrum of each model's test error against the label-noise floor
(which band the error lies in, and how far above the floor). Both are drawn from the predictions
through the label filter that the tables score, on the evaluated stretches of the test part.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.inputs import Motion
from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.statistics import estimate_noise
from id_learning.evaluation.findings import model_label
from id_learning.evaluation.report_figures import model_styles, pyplot, save_figure
from id_learning.evaluation.spectra import filtered_noise_density, power_spectral_density

__all__ = [
    'OVERLAY_SECONDS',
    'SPECTRUM_SEGMENT_S',
    'LabelFloor',
    'label_floor',
    'plot_error_spectra',
    'plot_torque_overlay',
    'richest_window',
    'stretches_of',
]

#: Length of the window shown in the torque overlays [s].
OVERLAY_SECONDS = 10.0
#: Shortest Welch segment of the error spectra [s]; longer where a cut-off is lower, so that
#: the label filter's cut-off lies eight bins up.
SPECTRUM_SEGMENT_S = 20.0


@dataclass(frozen=True)
class LabelFloor:
    """The label-noise floor the figures draw, and what it is.

    Attributes:
        rms_nm: (n,) RMS of the filtered label noise on the evaluated rows [N*m].
        label: how the figures name it (measured against the truth, or estimated).
    """

    rms_nm: np.ndarray
    label: str


def label_floor(
    dataset: Dataset, rows: np.ndarray, noise_floor: np.ndarray | None
) -> LabelFloor | None:
    """The report's label-noise floor, or else one estimated from the raw labels' high band.

    With the noise-free torque (a twin recording) the floor is the report's own figure
    (``scoring.label_noise_floor``); without it, the white level above the cut-offs carried
    through the label filter (``dataset.statistics.estimate_noise``). None when the evaluated
    rows are too few to estimate from.
    """
    if noise_floor is not None:
        return LabelFloor(np.asarray(noise_floor, dtype=float), 'label-noise floor')
    if len(rows) < 64:
        return None
    noise = estimate_noise(
        dataset.tau_raw[rows], dataset.cutoff_hz, dataset.period_s, dataset.filter_order
    )
    return LabelFloor(noise.filtered_std_nm, "label-noise estimate (raw label's high band)")


def stretches_of(rows: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """The [start, stop) ranges the dataset row ranges ``rows`` take in their concatenation."""
    stops = np.cumsum([b - a for a, b in rows])
    return [(int(stop - (b - a)), int(stop)) for (a, b), stop in zip(rows, stops, strict=True)]


def _in_spreads(x: np.ndarray) -> np.ndarray:
    """Each column of x (N, n) in units of its standard deviation (a still column as is)."""
    spread = x.std(axis=0)
    return x / np.where(spread > 0, spread, 1.0)


def richest_window(
    motion: Motion, rows: Sequence[tuple[int, int]], samples: int
) -> tuple[int, int]:
    """The dataset rows [start, stop) of the window of ``samples`` where the motion is richest.

    Richest: the largest mean over the window of sum_j (v_j / s_vj)^2 + (a_j / s_aj)^2, each
    joint's velocity and acceleration in units of its spread on the evaluated rows, so that
    every joint counts and a window where all of them move and reverse wins. The window lies
    inside one range of ``rows``; the longest range whole when none holds ``samples``.
    """
    index = np.concatenate([np.arange(a, b) for a, b in rows])
    score = np.sum(_in_spreads(motion.v[index]) ** 2 + _in_spreads(motion.a[index]) ** 2, axis=1)
    best, best_score = max(rows, key=lambda r: r[1] - r[0]), -np.inf
    for (start, stop), (c, d) in zip(rows, stretches_of(rows), strict=True):
        if stop - start < samples:
            continue
        sums = np.cumsum(np.concatenate([[0.0], score[c:d]]))
        means = sums[samples:] - sums[:-samples]
        k = int(np.argmax(means))
        if means[k] > best_score:
            best, best_score = (start + k, start + k + samples), float(means[k])
    return best


def plot_torque_overlay(
    *,
    t: np.ndarray,
    label: np.ndarray,
    prediction: np.ndarray,
    joints: tuple[str, ...],
    kind: str,
    target: str,
    path: Path,
) -> None:
    """One model's torque against the label on a window, one panel per joint.

    Args:
        t: (W,) time in the test part [s].
        label: (W, n) the filtered label [N*m].
        prediction: (W, n) the model's torque through the label filter [N*m].
        joints: the joint names.
        kind: the model's kind.
        target: 'motor' (tau_u labels) or 'joint'.
        path: the PNG to write.
    """
    plt = pyplot()
    n = len(joints)
    cols = 2 if n > 3 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(6.2 * cols, 2.3 * rows + 0.9),
        sharex=True,
        squeeze=False,
        constrained_layout=True,
    )
    colour = model_styles([kind])[kind]['color']
    name = 'tau_u' if target == 'motor' else 'tau'
    for j in range(rows * cols):
        ax = axes.flat[j]
        if j >= n:
            ax.set_visible(False)
            continue
        rms = float(np.sqrt(np.mean((prediction[:, j] - label[:, j]) ** 2)))
        ax.plot(t, label[:, j], color='k', lw=2.0, label=f'measured {name} (filtered label)')
        ax.plot(
            t,
            prediction[:, j],
            color=colour,
            lw=1.3,
            ls=(0, (5, 1.5)),
            label=f'{model_label(kind)} (through the label filter)',
        )
        ax.set_title(f'{joints[j]}: RMSE {rms:.3g} N·m in this window', fontsize=9)
        ax.set_ylabel('[N·m]')
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel('time in the test part [s]')
    axes.flat[0].legend(fontsize=8, loc='best')
    fig.suptitle(
        f'{model_label(kind)}: predicted against measured {name}, {t[-1] - t[0]:.0f} s of the '
        'test part where the motion is richest'
    )
    save_figure(fig, path)


def _spectrum_axes(ax: Any, joint: str, cutoff: float, top_hz: float) -> None:
    """Log axes, the cut-off marked, the title."""
    ax.axvline(cutoff, color='0.5', ls=':', lw=1.0)
    ax.text(
        cutoff,
        0.97,
        f' cut-off {cutoff:g} Hz',
        transform=ax.get_xaxis_transform(),
        fontsize=7,
        color='0.4',
        va='top',
    )
    ax.set_xscale('log')
    ax.set_yscale('log')
    ax.set_title(joint, fontsize=9)
    ax.grid(alpha=0.3, which='both')
    ax.set_xlim(right=top_hz)


def plot_error_spectra(
    *,
    errors: dict[str, np.ndarray],
    stretches: Sequence[tuple[int, int]],
    dataset: Dataset,
    floor: LabelFloor | None,
    path: Path,
    full_band: bool = False,
) -> None:
    """The amplitude spectral density of each model's test error per joint, with the floor.

    Args:
        errors: per kind, (N_eval, n) prediction minus label on the evaluated rows [N*m].
        stretches: the [start, stop) ranges of the error rows, each contiguous in time.
        dataset: the data (joints, sample period, the label filter).
        floor: the label-noise floor, drawn as white noise through the label filter.
        path: the PNG to write.
        full_band: errors of the torque the drive needs (unfiltered, up to Nyquist) rather
            than through the label filter.
    """
    plt = pyplot()
    ds, kinds = dataset, list(errors)
    styles = model_styles(kinds)
    segment_s = max(SPECTRUM_SEGMENT_S, 8.0 / float(np.min(ds.cutoff_hz)))
    spectra = {}
    for kind in kinds:
        freqs, psd = power_spectral_density(
            errors[kind], ds.period_s, stretches=stretches, segment_s=segment_s
        )
        spectra[kind] = np.sqrt(psd)
    floor_asd = (
        np.sqrt(
            filtered_noise_density(floor.rms_nm, ds.cutoff_hz, ds.period_s, ds.filter_order, freqs)
        )
        if floor is not None
        else None
    )
    n = len(ds.joints)
    cols = 3 if n > 3 else n
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.6 * cols, 3.3 * rows + 1.2), squeeze=False, constrained_layout=True
    )
    shown = slice(1, None)  # no zero frequency on a log axis
    for j in range(rows * cols):
        ax = axes.flat[j]
        if j >= n:
            ax.set_visible(False)
            continue
        top_hz = 0.5 / ds.period_s if full_band else min(0.5 / ds.period_s, 6.0 * ds.cutoff_hz[j])
        band = (freqs > 0) & (freqs <= top_hz)
        for kind in kinds:
            ax.plot(
                freqs[shown],
                spectra[kind][shown, j],
                lw=1.2,
                label=model_label(kind),
                **styles[kind],
            )
        if floor_asd is not None and floor is not None:
            ax.plot(
                freqs[shown],
                floor_asd[shown, j],
                color='k',
                lw=1.8,
                ls='--',
                zorder=5,
                label=f'{floor.label}, white through the label filter',
            )
        peak = max(float(np.max(s[band, j])) for s in spectra.values())
        ax.set_ylim(max(peak * 1e-5, 1e-12), peak * 3.0)
        _spectrum_axes(ax, ds.joints[j], float(ds.cutoff_hz[j]), top_hz)
        ax.set_xlim(left=freqs[1])
        if j % cols == 0:
            ax.set_ylabel('test error ASD [N·m/√Hz]')
        if j >= n - cols:
            ax.set_xlabel('frequency [Hz]')
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc='outside lower center', ncol=min(len(labels), 4), fontsize=8)
    what = (
        'the feed-forward on the planned reference minus the torque the drive needs'
        if full_band
        else 'prediction through the label filter minus label'
    )
    fig.suptitle(
        f'Amplitude spectral density of the test error ({what}; Welch, {segment_s:.0f} s segments)'
    )
    save_figure(fig, path)
