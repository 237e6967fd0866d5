"""Files of one import that overlap: rows one file holds that another holds too.

A log split into files that overlap (an export cut twice over one stretch, a logger that repeats
the rows around a file change) would put those samples into the bag twice, as two segments: the
end of one segment's test part would be the start of another's training part. A row of two files
is the same sample when every mapped value (positions, velocities, currents, torques, after
conversion) is equal, whatever its time: like the refusal of a whole log given twice, a copy
whose time column was shifted (re-based to 0 by an export) is the same data. Rows at rest (equal
to both neighbours) are left out, since a still arm repeats itself; two distinct logs of a moving
arm never share a row, their currents and velocities alone differ by noise. Files given twice
whole are refused before (``bag.distinct.check_distinct``,
``import_resample.check_distinct_samples``).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from id_learning.errors import ConfigError

__all__ = ['MIN_SHARED_ROWS', 'SourceRows', 'check_shared_rows', 'shared_rows']

logger = logging.getLogger(__name__)

#: Files sharing this many moving rows are refused; fewer (a row repeated at a file change) are
#: named in a warning and kept.
MIN_SHARED_ROWS = 10


@dataclass(frozen=True)
class SourceRows:
    """A file's rows as read and kept, to compare with the other files of an import.

    Attributes:
        source: the log file.
        label: what ``positions`` count: 'line' (CSV) or 'row' (NPZ).
        positions: (N,) line or row of each kept row.
        time: (N,) the time column as logged (its unit), or None without a time column.
        values: (N, n) SI values per quantity ('position' among them).
    """

    source: Path
    label: str
    positions: np.ndarray
    time: np.ndarray | None
    values: dict[str, np.ndarray]

    def moving(self) -> np.ndarray:
        """(N,) True for rows whose positions differ from the row before or after."""
        q = self.values['position']
        step = np.any(q[1:] != q[:-1], axis=1)
        out = np.zeros(len(q), dtype=bool)
        out[1:] |= step
        out[:-1] |= step
        return out

    def keys(self) -> np.ndarray:
        """(N,) one comparable key per row: its values as float64 bytes (not its time)."""
        columns = [np.asarray(self.values[key], dtype=np.float64) for key in sorted(self.values)]
        rows = np.ascontiguousarray(np.hstack(columns)) + 0.0  # -0.0 as 0.0
        return rows.view(np.dtype((np.void, rows.itemsize * rows.shape[1]))).ravel()


def shared_rows(files: Sequence[SourceRows]) -> dict[tuple[int, int], np.ndarray]:
    """Per pair of files (i < j), the (k, 2) row indices of the moving rows both hold.

    Overlapping files hold a stretch of rows in common: the rows of one at a fixed distance (in
    lines or NPZ rows) from those of the other. Only the pairs at the most common distance are
    kept, so that a sample two logs of one motion at other rates hold by coincidence (their
    common instants) is not taken for an overlap. One sort over all files' moving rows, so that
    many files cost little more than one.
    """
    moving = [np.flatnonzero(f.moving()) for f in files]
    if sum(len(rows) for rows in moving) == 0:
        return {}
    keys = np.concatenate([f.keys()[rows] for f, rows in zip(files, moving, strict=True)])
    owner = np.concatenate([np.full(len(rows), i) for i, rows in enumerate(moving)])
    index = np.concatenate(moving)
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    repeated = np.flatnonzero(counts[inverse] > 1)
    repeated = repeated[np.argsort(inverse[repeated], kind='stable')]
    pairs: dict[tuple[int, int], list[tuple[int, int]]] = {}
    groups = np.split(repeated, np.flatnonzero(np.diff(inverse[repeated])) + 1)
    for group in (g for g in groups if g.size):
        first: dict[int, int] = {}  # per file, its first row with this key
        for member in group:
            first.setdefault(int(owner[member]), int(index[member]))
        for (i, row_i), (j, row_j) in itertools.combinations(sorted(first.items()), 2):
            pairs.setdefault((i, j), []).append((row_i, row_j))
    return {(i, j): _one_shift(files[i], files[j], rows) for (i, j), rows in pairs.items()}


def _one_shift(first: SourceRows, second: SourceRows, rows: list[tuple[int, int]]) -> np.ndarray:
    """The (k, 2) pairs of ``rows`` at the most common distance between their positions."""
    at = np.array(sorted(rows))
    shift = second.positions[at[:, 1]] - first.positions[at[:, 0]]
    values, counts = np.unique(shift, return_counts=True)
    kept: np.ndarray = at[shift == values[np.argmax(counts)]]
    return kept


def _span(rows: SourceRows, at: np.ndarray) -> str:
    first, last = int(rows.positions[at.min()]), int(rows.positions[at.max()])
    return f'{rows.label} {first}' if first == last else f'{rows.label}s {first}-{last}'


def _times(rows: SourceRows, at: np.ndarray) -> str:
    times = np.asarray(rows.time)[at]
    return f'{times.min():.15g} to {times.max():.15g}'


def _described(first: SourceRows, second: SourceRows, at: np.ndarray, column: str) -> str:
    """'b.csv lines 2-501 repeat 500 rows of a.csv lines 1502-2001 (time_ms 12000 to 15992)'."""
    in_first, in_second = at[:, 0], at[:, 1]
    text = (
        f'{second.source} {_span(second, in_second)} repeat{"s" if len(at) == 1 else ""} '
        f'{len(at)} row{"s" if len(at) > 1 else ""} of {first.source} {_span(first, in_first)}'
    )
    if first.time is None or second.time is None:
        return text
    span, other = _times(second, in_second), _times(first, in_first)
    shifted = '' if span == other else f' there, {other} in {first.source.name}'
    return f'{text} (time column {column} {span}{shifted})'


def check_shared_rows(files: Sequence[SourceRows], time_column: str = 'time') -> None:
    """Refuse files that share ``MIN_SHARED_ROWS`` moving rows; warn of fewer.

    Raises:
        ConfigError: the first pair of files that overlap: names both, the rows (CSV lines or
            NPZ rows) in each and the time span as logged.
    """
    for (i, j), at in sorted(shared_rows(files).items()):
        what = _described(files[i], files[j], at, time_column)
        if len(at) >= MIN_SHARED_ROWS:
            raise ConfigError(
                f'import: {what}: the files overlap, so these samples would be in the bag twice '
                '(the test part of one segment would be training data of another); cut the '
                'overlap from one file'
            )
        logger.warning(
            'import: %s: these samples are in the bag twice; cut them from one file', what
        )
