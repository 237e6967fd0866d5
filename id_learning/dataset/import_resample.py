"""An imported log on the robot's sampling grid, in segments: snapped or resampled.

Two policies (``ResamplePolicy.method``):

- 'snap', for logs written on the controller's own grid: each stamp within the jitter tolerance
  of a grid point is moved onto it, values untouched; missing grid points stay gaps;
- 'interpolate', for logs at another rate, with jitter or a drifting clock: the stamps are taken
  as the truth and every signal is evaluated on a new uniform grid. Positions and velocities are
  interpolated by cubic splines through the logged samples. Currents and torques, which carry
  the drives' ripple and noise up to the log's Nyquist frequency, first pass a zero-phase
  anti-aliasing low-pass at 0.8 times the grid's Nyquist frequency when the log is faster than
  the grid, and are then interpolated linearly (no overshoot on noisy signals).

Either way a pause longer than ``max_gap_s`` ends a segment (segments are never bridged and are
preprocessed on their own), and segments shorter than ``min_segment_s`` are dropped; both are
reported with the lines around them.
"""

from __future__ import annotations

import hashlib
import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from id_learning.dataset.import_mapping import ResamplePolicy
from id_learning.errors import ConfigError

__all__ = [
    'GAP_PERIODS',
    'Gridded',
    'Segment',
    'check_distinct_samples',
    'interpolate_segments',
    'slot_segments',
]

#: Default longest pause inside a segment, in grid periods (what loading a bag tolerates).
GAP_PERIODS = 3.0
#: A source step longer than this many median steps is a hole that interpolation bridges.
_HOLE_STEPS = 1.5
#: The anti-aliasing cut-off as a fraction of the grid's Nyquist frequency.
_ANTIALIAS_NYQUIST_FRACTION = 0.8
_ANTIALIAS_ORDER = 4


@dataclass(frozen=True)
class Segment:
    """A stretch of the log without a long pause, on the grid.

    Attributes:
        slots: (k,) grid indices of the samples, counted from the file's first grid point.
        values: (k, n) SI values per quantity.
        first, last: position (line or row) of the first and last source row it was made from.
    """

    slots: np.ndarray
    values: dict[str, np.ndarray]
    first: int
    last: int


@dataclass
class Gridded:
    """A log on the grid, and what it took to get there.

    Attributes:
        segments: the segments kept, in time order.
        period_s: the grid period [s].
        source_step_s: the log's median time step [s].
        mean_step_s: the log's mean step inside segments [s]: above the median when samples are
            missing, off the nominal rate when the logger's clock drifts.
        max_jitter_s: 'snap': the largest stamp moved onto the grid [s].
        n_snapped: 'snap': stamps moved onto the grid.
        n_gaps: 'snap': grid points left empty inside segments (loading fills them).
        n_filled: 'interpolate': grid points that lie in a hole of the log (a step above 1.5
            median steps), bridged by interpolation.
        holes: 'interpolate': (position before, position after, seconds) of each hole bridged.
        breaks: (position before, position after, seconds) of each pause that ends a segment.
        short: (first position, last position, seconds) of each segment dropped as too short.
        start_ns: the time of grid slot 0 [ns since the epoch] when the log's time column is
            absolute (``import_stamps.absolute_start_ns``), else None: the importer re-bases.
    """

    segments: list[Segment]
    period_s: float
    source_step_s: float
    mean_step_s: float
    max_jitter_s: float = 0.0
    n_snapped: int = 0
    n_gaps: int = 0
    n_filled: int = 0
    holes: list[tuple[int, int, float]] = field(default_factory=list)
    breaks: list[tuple[int, int, float]] = field(default_factory=list)
    short: list[tuple[int, int, float]] = field(default_factory=list)
    start_ns: int | None = None


def _samples_digest(grid: Gridded) -> str:
    """SHA-256 of the gridded samples: each segment's grid slots and SI values (-0.0 as 0.0)."""
    digest = hashlib.sha256()
    for segment in grid.segments:
        digest.update(np.int64(len(segment.slots)).tobytes())
        digest.update(np.ascontiguousarray(segment.slots, dtype=np.int64).tobytes())
        for key in sorted(segment.values):
            digest.update(key.encode())
            values = np.ascontiguousarray(segment.values[key], dtype=np.float64) + 0.0
            digest.update(values.tobytes())
    return digest.hexdigest()


def check_distinct_samples(grids: Sequence[Gridded], sources: Sequence[Path]) -> None:
    """Refuse two files whose samples on the grid are identical: one recording weighed twice.

    Byte-identical copies are refused before reading (``bag.distinct.check_distinct``); this
    catches the same samples in other bytes: other float formatting or line endings, a CSV and
    its NPZ export, a gzipped copy, or stamps shifted by a constant (slots count from a file's
    first grid point).

    Raises:
        ConfigError: names both files.
    """
    seen: dict[str, Path] = {}
    for grid, source in zip(grids, sources, strict=True):
        digest = _samples_digest(grid)
        if digest in seen:
            n = sum(len(segment.slots) for segment in grid.segments)
            raise ConfigError(
                f'import: {source} holds the same samples as {seen[digest]} ({n} samples, stamps '
                'and values identical after parsing); give each recording once'
            )
        seen[digest] = source


def _max_gap_s(policy: ResamplePolicy, period_s: float, step_s: float | None = None) -> float:
    """The longest pause inside a segment [s].

    The policy's, else 3 grid periods (3 log steps when the log is slower and resampled).

    Raises:
        ConfigError: a gap left unfilled ('snap') longer than loading a bag tolerates.
    """
    if policy.max_gap_s is None:
        return GAP_PERIODS * max(period_s, step_s or 0.0)
    if step_s is None and policy.max_gap_s > GAP_PERIODS * period_s * (1 + 1e-9):
        raise ConfigError(
            f'resample.max_gap_s {policy.max_gap_s:g} s: pauses are left unfilled when samples '
            f'are snapped, and loading a bag refuses gaps over {GAP_PERIODS:g} periods '
            f'({GAP_PERIODS * period_s:g} s); use at most that, or method: interpolate'
        )
    return policy.max_gap_s


def _stretches(
    times_s: np.ndarray, positions: np.ndarray, max_gap_s: float, out: Gridded
) -> list[slice]:
    """Split at pauses longer than ``max_gap_s`` (recorded in ``out.breaks``)."""
    steps = np.diff(times_s)
    cuts = np.flatnonzero(steps > max_gap_s * (1 + 1e-9)) + 1
    for cut in cuts:
        out.breaks.append((int(positions[cut - 1]), int(positions[cut]), float(steps[cut - 1])))
    bounds = [0, *cuts.tolist(), len(times_s)]
    return [slice(a, b) for a, b in itertools.pairwise(bounds)]


def _keep_long(
    stretch: slice,
    times_s: np.ndarray,
    positions: np.ndarray,
    policy: ResamplePolicy,
    out: Gridded,
) -> bool:
    duration = float(times_s[stretch.stop - 1] - times_s[stretch.start])
    if duration >= policy.min_segment_s and stretch.stop - stretch.start >= 2:
        return True
    out.short.append((int(positions[stretch.start]), int(positions[stretch.stop - 1]), duration))
    return False


def _step_stats(times_s: np.ndarray, stretches: list[slice]) -> tuple[float, float]:
    steps = np.diff(times_s)
    inside = np.concatenate([np.diff(times_s[s]) for s in stretches]) if stretches else steps
    inside = inside if inside.size else steps
    return float(np.median(steps)), float(np.mean(inside))


def slot_segments(
    slots: np.ndarray,
    values: dict[str, np.ndarray],
    positions: np.ndarray,
    period_s: float,
    policy: ResamplePolicy,
) -> Gridded:
    """Segments of rows already on the grid at ``slots`` ('snap', or a fixed period).

    Args:
        slots: (N,) strictly increasing grid indices of the rows.
        values: (N, n) SI values per quantity.
        positions: (N,) line or row of each row, for the report.
        period_s: the grid period [s].
        policy: the mapping's resample policy (gap and segment lengths).
    """
    times_s = (slots - slots[0]) * period_s
    out = Gridded([], period_s, 0.0, 0.0)
    stretches = _stretches(times_s, positions, _max_gap_s(policy, period_s), out)
    kept = [s for s in stretches if _keep_long(s, times_s, positions, policy, out)]
    out.source_step_s, out.mean_step_s = _step_stats(times_s, kept)
    for s in kept:
        out.n_gaps += int(np.sum(np.diff(slots[s]) - 1))
        out.segments.append(
            Segment(
                slots[s] - slots[0],
                {key: array[s] for key, array in values.items()},
                int(positions[s.start]),
                int(positions[s.stop - 1]),
            )
        )
    return out


def interpolate_segments(
    times_s: np.ndarray,
    values: dict[str, np.ndarray],
    positions: np.ndarray,
    period_s: float,
    policy: ResamplePolicy,
) -> Gridded:
    """Resample rows at strictly increasing ``times_s`` [s, from the first] onto the grid.

    Grid point k lies at k * period_s from the first row; each segment takes the grid points
    inside its time span.
    """
    out = Gridded([], period_s, 0.0, 0.0)
    median_step = float(np.median(np.diff(times_s)))
    stretches = _stretches(times_s, positions, _max_gap_s(policy, period_s, median_step), out)
    kept = [s for s in stretches if _keep_long(s, times_s, positions, policy, out)]
    out.source_step_s, out.mean_step_s = _step_stats(times_s, kept)
    for s in kept:
        t = times_s[s]
        slots = np.arange(np.ceil(t[0] / period_s - 1e-9), np.floor(t[-1] / period_s + 1e-9) + 1)
        slots = slots.astype(np.int64)
        if slots.size < 2:
            out.short.append((int(positions[s.start]), int(positions[s.stop - 1]), t[-1] - t[0]))
            continue
        _record_holes(t, positions[s], slots * period_s, out.source_step_s, out)
        resampled = {
            key: _resample(
                t, array[s], slots * period_s, key, step_s=out.source_step_s, period_s=period_s
            )
            for key, array in values.items()
        }
        out.segments.append(
            Segment(slots, resampled, int(positions[s.start]), int(positions[s.stop - 1]))
        )
    return out


def _record_holes(
    t: np.ndarray, positions: np.ndarray, grid_t: np.ndarray, step_s: float, out: Gridded
) -> None:
    steps = np.diff(t)
    for i in np.flatnonzero(steps > _HOLE_STEPS * step_s):
        inside = (grid_t > t[i]) & (grid_t < t[i + 1])
        out.n_filled += int(np.count_nonzero(inside))
        out.holes.append((int(positions[i]), int(positions[i + 1]), float(steps[i])))


def _resample(
    t: np.ndarray,
    x: np.ndarray,
    grid_t: np.ndarray,
    quantity: str,
    *,
    step_s: float,
    period_s: float,
) -> np.ndarray:
    """(k, n) values of x (m, n) at times t, evaluated at grid_t (see the module docstring)."""
    from scipy.interpolate import CubicSpline

    if quantity in ('position', 'velocity'):
        if len(t) >= 4:
            return np.asarray(CubicSpline(t, x, axis=0)(grid_t))
    elif step_s * (1.0 + 1e-6) < period_s:
        t, x = _antialiased(t, x, step_s, period_s)
    return np.column_stack([np.interp(grid_t, t, x[:, j]) for j in range(x.shape[1])])


def _antialiased(
    t: np.ndarray, x: np.ndarray, step_s: float, period_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """X low-passed below the grid's Nyquist frequency, on a uniform grid of the log's step."""
    from scipy import signal

    uniform = np.linspace(t[0], t[-1], round((t[-1] - t[0]) / step_s) + 1)
    if len(uniform) < 2 * (2 * _ANTIALIAS_ORDER + 1):
        return t, x  # too short to filter; so short a segment is dropped or nearly so
    on_uniform = np.column_stack([np.interp(uniform, t, x[:, j]) for j in range(x.shape[1])])
    cutoff_hz = _ANTIALIAS_NYQUIST_FRACTION * 0.5 / period_s
    fs = (len(uniform) - 1) / (uniform[-1] - uniform[0])  # below 1.25 / period: cut-off < Nyquist
    sos = signal.butter(_ANTIALIAS_ORDER, cutoff_hz, fs=fs, output='sos')
    return uniform, signal.sosfiltfilt(sos, on_uniform, axis=0)
