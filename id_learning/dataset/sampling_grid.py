"""The IPO grid a recording's stamps must lie on, and how a topic's stamps contradict it.

One rule for train (``preprocess.regularise`` snaps onto the grid), inspect and the replay
(``sampling_problem`` names a topic sampled at another period than the robot's).
"""

from __future__ import annotations

import numpy as np

__all__ = ['SAMPLING_MAX_PERIODS', 'SAMPLING_TOLERANCE', 'grid_slots', 'sampling_problem']

#: A stamp within this share of the IPO period from the IPO grid is on it
#: (``PreprocessConfig.jitter_tolerance``'s default: train refuses stamps further off).
SAMPLING_TOLERANCE = 0.25
#: Train refuses steps longer than this many IPO periods as gaps (``load_recording``'s default).
SAMPLING_MAX_PERIODS = 3.0


def grid_slots(
    stamps_ns: np.ndarray, period_ns: float, origin_ns: np.ndarray | int
) -> tuple[np.ndarray, np.ndarray]:
    """Each stamp's IPO slot counted from ``origin_ns``, and its distance from that slot [ns].

    The grid ``preprocess.regularise`` snaps a recording onto, and ``sampling_problem`` judges.
    """
    offsets = (np.asarray(stamps_ns, dtype=np.int64) - origin_ns).astype(float)
    slots = np.round(offsets / period_ns).astype(np.int64)
    return slots, np.abs(offsets - slots * period_ns)


def sampling_problem(stamps_ns: np.ndarray, period_s: float, where: str) -> str | None:
    """How a topic's stamps contradict the robot's IPO period, or None when they do not.

    Train's rule (``preprocess.regularise``): every stamp lies within ``SAMPLING_TOLERANCE``
    periods of the IPO grid laid from its stretch's first stamp, one per slot; whole multiples up
    to ``SAMPLING_MAX_PERIODS`` periods are filled by interpolation, longer steps are gaps
    (``load_recording``). A stretch ends at such a gap or a stamp that does not increase (both
    reported on their own). The median positive step names the sampling period found.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    steps = np.diff(stamps)
    positive = steps[steps > 0]
    if not positive.size or not period_s > 0:
        return None
    period_ns = period_s * 1e9
    step_s = float(np.median(positive)) * 1e-9
    ratio = step_s / period_s
    head = (
        f"{where}: sampled every {step_s * 1e3:.4g} ms (median stamp step), the robot's IPO "
        f'period is {period_s * 1e3:g} ms'
    )
    remedy = 'record at the IPO period, or give the robot config whose ipo_period_s it has'
    whole = round(ratio)
    if abs(ratio - whole) <= SAMPLING_TOLERANCE and 2 <= whole <= SAMPLING_MAX_PERIODS:
        return (
            f'{head}: one sample every {whole} IPO cycles, so train fills {whole - 1} of '
            f'{whole} samples by interpolation; {remedy}'
        )
    if ratio > SAMPLING_MAX_PERIODS:
        return (
            f'{head}: train refuses steps over {SAMPLING_MAX_PERIODS:g} periods as gaps; {remedy}'
        )
    breaks = (steps <= 0) | (steps > SAMPLING_MAX_PERIODS * period_ns)
    starts = np.concatenate(([0], np.flatnonzero(breaks) + 1))
    origin = stamps[starts[np.searchsorted(starts, np.arange(stamps.size), side='right') - 1]]
    _, jitter = grid_slots(stamps, period_ns, origin)
    off = np.flatnonzero(jitter > SAMPLING_TOLERANCE * period_ns)
    if not off.size and abs(ratio - 1.0) <= SAMPLING_TOLERANCE:
        return None
    k = int(off[0]) if off.size else 1
    return (
        f'{head}: sample {k} (stamp {int(stamps[k])} ns) lies {jitter[k] * 1e-6:.3f} ms off the '
        f'IPO grid, and train refuses stamps more than {SAMPLING_TOLERANCE:.0%} of a period off '
        f'it; {remedy}'
    )
