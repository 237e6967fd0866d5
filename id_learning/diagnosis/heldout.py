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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from id_learning.dataset.blocks import (
    MIN_BLOCKS,
    block_gains,
    block_ids,
    block_length_s,
    holm,
    one_sided_p,
)
from id_learning.diagnosis.design import Design, Fit
from id_learning.diagnosis.problem import ResidualProblem

__all__ = [
    'MIN_BLOCKS',
    'BlockTest',
    'fallback_joints',
    'judge_effects',
    'test_blocks',
    'time_blocks',
]


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
    seconds_per_row = problem.step * problem.period
    block_s = block_length_s(residual, seconds_per_row)
    ends = np.cumsum([len(r.rows[part]) for r in problem.recordings])[:-1]
    return block_ids(problem.times(part), block_s, seconds_per_row, ends), block_s


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
        gains = block_gains(without, with_all, blocks).sum(axis=1)
        raw[label] = (one_sided_p(gains), len(gains), float(np.mean(gains)))
    return {
        label: BlockTest(p, raw[label][1], block_s, raw[label][2])
        for label, p in holm({label: value[0] for label, value in raw.items()}).items()
    }


def fallback_joints(design: Design, final: Fit, blocks: np.ndarray) -> list[int]:
    """Joints the effects act on but do not improve on the held-out part: left to the nominal.

    A joint keeps its effects when their mean gain over the blocks is positive. (Not only where
    that gain is significant on the joint alone: a robot-wide effect, a delay or a payload, is
    judged on all joints together and leaves a small, real share on each.)
    """
    after = design.residual(final, 'test')
    gains = block_gains(design.y['test'], after, blocks)
    touched = np.any(after != design.y['test'], axis=0)
    return [int(j) for j in np.flatnonzero(touched) if not float(np.mean(gains[:, j])) > 0]
