"""Held-out gains judged over blocks of time, not sample by sample.

A model's residual is correlated over far more samples than the label filter alone explains on
real robots, so sample-wise statistics overstate what a held-out part shows. A held-out part is
cut into blocks of time longer than the residual's correlation (never across a recording's end
or a seam), each block gives one gain (the share of each joint's mean square that the larger
model removes), and a one-sided t test over the blocks judges it. The identification
(``physics.identification``) and the diagnosis (``diagnosis.heldout``) both judge this way.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import stats

from id_learning.dataset.statistics import integrated_autocorrelation

__all__ = ['MIN_BLOCKS', 'block_gains', 'block_ids', 'block_length_s', 'holm', 'one_sided_p']

#: Fewer blocks than this judge nothing (a t test over 4 blocks says little).
MIN_BLOCKS = 5
#: Blocks span at least this many residual correlation times, and at least 1 s.
_CORRELATION_TIMES = 2.0
_MIN_BLOCK_S = 1.0
#: A step of more than this many rows' spacing is a seam between recordings.
_SEAM_ROWS = 3.0


def block_length_s(residual: np.ndarray, seconds_per_row: float) -> float:
    """The larger of 1 s and twice the residual's (N, n) correlation time on any joint [s]."""
    correlation_s = max(
        integrated_autocorrelation(residual[:, j]) * seconds_per_row
        for j in range(residual.shape[1])
    )
    return max(_MIN_BLOCK_S, _CORRELATION_TIMES * float(correlation_s))


def block_ids(
    times: np.ndarray, block_s: float, seconds_per_row: float, ends: np.ndarray | None = None
) -> np.ndarray:
    """(N,) block index of each row at ``times`` [s], blocks ``block_s`` long.

    A run of rows ends at each index in ``ends`` and wherever time jumps or goes back (a seam
    between recordings); a run's last block shorter than half a block joins the one before.
    """
    steps = np.diff(times)
    seams = np.flatnonzero((steps <= 0) | (steps > _SEAM_ROWS * seconds_per_row)) + 1
    cuts = set(seams.tolist()) | set(() if ends is None else np.asarray(ends).tolist())
    bounds = [0, *sorted(cuts), len(times)]
    ids = np.empty(len(times), dtype=np.int64)
    next_id = 0
    for a, b in itertools.pairwise(bounds):
        if b <= a:
            continue
        t = times[a:b] - times[a]
        local = np.floor(t / block_s).astype(np.int64)
        if local.max() > 0 and t[-1] - local.max() * block_s < block_s / 2:
            local[local == local.max()] -= 1
        ids[a:b] = local + next_id
        next_id += int(local.max()) + 1
    return ids


def block_gains(worse: np.ndarray, better: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """(B, n) per block and joint: the share of ``worse``'s mean square that ``better`` removes.

    Shares per block, not amounts, so that blocks of strong and of weak excitation weigh alike.
    """
    labels = np.unique(blocks)
    out = np.zeros((len(labels), worse.shape[1]))
    for k, label in enumerate(labels):
        rows = blocks == label
        before = np.mean(worse[rows] ** 2, axis=0)
        after = np.mean(better[rows] ** 2, axis=0)
        out[k] = np.where(before > 0, (before - after) / np.where(before > 0, before, 1.0), 0.0)
    return out


def one_sided_p(gains: np.ndarray) -> float:
    """The one-sided p of 'mean gain <= 0', a t test over the blocks; nan with too few."""
    if len(gains) < MIN_BLOCKS:
        return float('nan')
    spread = float(np.std(gains, ddof=1))
    if spread == 0.0:
        return 0.0 if float(np.mean(gains)) > 0 else 1.0
    t = float(np.mean(gains)) / (spread / np.sqrt(len(gains)))
    return float(stats.t.sf(t, len(gains) - 1))


def holm(p_values: dict[str, float]) -> dict[str, float]:
    """Holm's step-down adjustment (nan stays nan)."""
    judged = sorted((p, label) for label, p in p_values.items() if not np.isnan(p))
    out = {label: p for label, p in p_values.items() if np.isnan(p)}
    running, m = 0.0, len(judged)
    for k, (p, label) in enumerate(judged):
        running = max(running, min(1.0, (m - k) * p))
        out[label] = running
    return out
