"""Judging the diagnosis on held-out data in whole blocks of time, not sample by sample.

A residual is correlated over far more samples than the label filter alone explains on real
robots, so sample-wise statistics overstate what a held-out part shows. Here the held-out part
is cut into blocks of time longer than the residual's correlation (never across a recording's
end), and an effect's gain is judged by a one-sided t test over the blocks' gains:

- ``judge_effects``: each effect dropped from the final model, its held-out gain over the blocks
  (scale-free: in each block, the share of each joint's mean square it removes), Holm-corrected
  over the effects; with fewer than ``MIN_BLOCKS`` blocks nothing can be judged (p = nan);
- ``fallback_joints``: the joints on which the effects do not improve the held-out part, which
  the model then leaves to the nominal model.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from id_learning.dataset.statistics import integrated_autocorrelation
from id_learning.diagnosis.problem import ResidualProblem
from id_learning.diagnosis.selection import Design, Fit

__all__ = [
    'MIN_BLOCKS',
    'BlockTest',
    'fallback_joints',
    'judge_effects',
    'test_blocks',
    'time_blocks',
]

#: Fewer blocks than this judge nothing (a t test over 4 blocks says little).
MIN_BLOCKS = 5
#: Blocks span at least this many residual correlation times, and at least 1 s.
_CORRELATION_TIMES = 2.0
_MIN_BLOCK_S = 1.0
#: A step of more than this many kept rows' spacing is a seam between recordings.
_SEAM_ROWS = 3.0


@dataclass(frozen=True)
class BlockTest:
    """A held-out gain judged over blocks of time.

    Attributes:
        p_value: one-sided p of 'no gain' (Holm-corrected in ``judge_effects``); nan: too few
            blocks to judge.
        n_blocks: blocks of the held-out part.
        block_s: their length [s].
        gain: mean gain over the blocks: per block, the share of the mean square without the
            effect that it removes, summed over joints (1 = one joint's whole disagreement).
    """

    p_value: float
    n_blocks: int
    block_s: float
    gain: float

    @property
    def judged(self) -> bool:
        """Enough blocks to judge."""
        return not np.isnan(self.p_value)


def test_blocks(problem: ResidualProblem, residual: np.ndarray) -> tuple[np.ndarray, float]:
    """(N_test,) block index of each held-out row, and the block length [s] (``time_blocks``)."""
    return time_blocks(problem, residual, 'test')


def time_blocks(
    problem: ResidualProblem, residual: np.ndarray, part: str
) -> tuple[np.ndarray, float]:
    """(N_part,) block index of each row of a part, and the block length [s].

    The length is the largest of 1 s and twice the correlation time on any joint of the
    ``residual`` (N_part, n) the model leaves, which is what makes blocks' gains scatter; a
    recording's last block shorter than half of it joins the one before.
    """
    y = residual
    seconds_per_row = problem.step * problem.period
    correlation_s = max(
        integrated_autocorrelation(y[:, j]) * seconds_per_row for j in range(y.shape[1])
    )
    block_s = max(_MIN_BLOCK_S, _CORRELATION_TIMES * float(correlation_s))
    times = problem.times(part)
    # A run of rows ends at a recording's end and wherever time jumps or goes back: a dataset
    # joined from several recordings (the training parts of a run's bags) holds seams.
    steps = np.diff(times)
    seams = np.flatnonzero((steps <= 0) | (steps > _SEAM_ROWS * seconds_per_row)) + 1
    ends = np.cumsum([len(r.rows[part]) for r in problem.recordings])[:-1]
    bounds = [0, *sorted(set(seams.tolist()) | set(ends.tolist())), len(times)]
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
    return ids, block_s


def _block_gains(worse: np.ndarray, better: np.ndarray, blocks: np.ndarray) -> np.ndarray:
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


def _one_sided(gains: np.ndarray) -> float:
    """The one-sided p of 'mean gain <= 0', a t test over the blocks; nan with too few."""
    if len(gains) < MIN_BLOCKS:
        return float('nan')
    spread = float(np.std(gains, ddof=1))
    if spread == 0.0:
        return 0.0 if float(np.mean(gains)) > 0 else 1.0
    t = float(np.mean(gains)) / (spread / np.sqrt(len(gains)))
    return float(stats.t.sf(t, len(gains) - 1))


def judge_effects(
    design: Design,
    selected: Sequence[str],
    final: Fit,
    blocks: np.ndarray,
    block_s: float,
) -> dict[str, BlockTest]:
    """Each effect's held-out gain over blocks, the others kept; Holm-corrected over effects."""
    with_all = design.residual(final, 'test')
    raw: dict[str, tuple[float, int, float]] = {}
    for label in selected:
        without = design.residual(design.fit([s for s in selected if s != label]), 'test')
        gains = _block_gains(without, with_all, blocks).sum(axis=1)
        raw[label] = (_one_sided(gains), len(gains), float(np.mean(gains)))
    return {
        label: BlockTest(p, raw[label][1], block_s, raw[label][2])
        for label, p in _holm({label: value[0] for label, value in raw.items()}).items()
    }


def _holm(p_values: dict[str, float]) -> dict[str, float]:
    """Holm's step-down adjustment (nan stays nan)."""
    judged = sorted((p, label) for label, p in p_values.items() if not np.isnan(p))
    out = {label: p for label, p in p_values.items() if np.isnan(p)}
    running, m = 0.0, len(judged)
    for k, (p, label) in enumerate(judged):
        running = max(running, min(1.0, (m - k) * p))
        out[label] = running
    return out


def fallback_joints(design: Design, final: Fit, blocks: np.ndarray) -> list[int]:
    """Joints the effects act on but do not improve on the held-out part: left to the nominal.

    A joint keeps its effects when their mean gain over the blocks is positive. (Not only where
    that gain is significant on the joint alone: a robot-wide effect, a delay or a payload, is
    judged on all joints together and leaves a small, real share on each.)
    """
    after = design.residual(final, 'test')
    gains = _block_gains(design.y['test'], after, blocks)
    touched = np.any(after != design.y['test'], axis=0)
    return [int(j) for j in np.flatnonzero(touched) if not float(np.mean(gains[:, j])) > 0]
