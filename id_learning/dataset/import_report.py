"""What the import of one log file did: ``ImportReport``, and its summary in a few lines."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from id_learning.dataset.import_resample import Gridded
from id_learning.dataset.inspect_checks import iso_utc

__all__ = ['ImportReport', 'TimeBase']

#: Where a file's stamps in the bag come from: 'absolute', the time column's own time (since
#: the epoch); 'relative', a time column that counts from some start, re-based; 'period', no
#: time column (``period_s``), re-based; 'given', re-based to the ``start_ns`` asked for;
#: 'mixed', an absolute time column while another file's is not, re-based.
TimeBase = Literal['absolute', 'relative', 'period', 'given', 'mixed']


@dataclass
class ImportReport:
    """What the import of one log file did; ``summary()`` gives it in a few lines.

    Attributes:
        source: the imported log file.
        out: the bag written.
        n_rows_read: data rows in the log (without header, comment and blank lines).
        n_rows_written: samples written to the bag from this file.
        period_s: sampling period of the written stamps [s].
        velocity_source: 'column' (mapped) or 'differentiated' (from position).
        row_label: what row positions count: 'line' (1-based CSV line, header and comments
            included) or 'row' (0-based NPZ array index).
        dropped_rows: (position, reason) of each row dropped under the NaN, implausible-value or
            beyond-limits policy; the reason names the column, its joint and the value.
        method: the resample policy's method.
        grid: what snapping or resampling did (steps, jitter, holes, pauses, short segments).
        start_ns: the bag stamp of this file's first sample [ns since epoch].
        time_base: where the stamps come from (``TimeBase``): kept from an absolute time column,
            or re-based.
        first_time_s: the time column's first value [s] (None without a time column).
        has_current: whether motor currents were mapped (the bag then has ``currents_topic``).
        has_joint_torque: whether joint torques were mapped (the joint states' effort).
        currents_topic: the topic of the motor currents in the bag.
    """

    source: Path
    out: Path
    n_rows_read: int
    n_rows_written: int
    period_s: float
    velocity_source: Literal['column', 'differentiated']
    row_label: Literal['line', 'row'] = 'line'
    dropped_rows: list[tuple[int, str]] = field(default_factory=list)
    method: Literal['snap', 'interpolate'] = 'snap'
    grid: Gridded | None = None
    start_ns: int = 0
    time_base: TimeBase = 'relative'
    first_time_s: float | None = None
    has_current: bool = True
    has_joint_torque: bool = False
    currents_topic: str = '/motor_currents'

    @property
    def n_segments(self) -> int:
        """Segments written from this file."""
        return 0 if self.grid is None else len(self.grid.segments)

    @property
    def max_jitter_s(self) -> float:
        """Largest |stamp - grid point| snapped [s]."""
        return 0.0 if self.grid is None else self.grid.max_jitter_s

    @property
    def n_snapped(self) -> int:
        """Stamps moved onto the grid."""
        return 0 if self.grid is None else self.grid.n_snapped

    @property
    def n_gaps(self) -> int:
        """Grid slots left empty inside segments (loading fills them)."""
        return 0 if self.grid is None else self.grid.n_gaps

    def _first_dropped(self) -> str:
        """Per kind of dropped row (its reason up to the column), the count and the first one."""
        kinds: dict[str, list[tuple[int, str]]] = {}
        for row, reason in self.dropped_rows:
            kinds.setdefault(reason.partition('column')[0], []).append((row, reason))
        return ''.join(
            f'\n    first of {len(rows)}: {self.row_label} {rows[0][0]}, {rows[0][1]}'
            for rows in kinds.values()
        )

    def time_note(self) -> str:
        """Where the stamps come from, and the bag's first stamp of this file."""
        first = iso_utc(self.start_ns)
        if self.time_base == 'absolute':
            return f"stamps keep the time column's absolute time: first sample at {first}"
        if self.time_base == 'relative' and self.first_time_s is not None:
            why = f'the time column starts at {self.first_time_s:.6g} s, not an epoch time'
        elif self.time_base == 'mixed':
            why = "the time column is absolute here but not in every file's"
        else:
            why = 'the start asked for' if self.time_base == 'given' else 'no time column'
        return f'stamps re-based ({why}): first sample at {first}'

    def label_note(self) -> str:
        """What train can learn from the bag, when it lacks motor currents ('' with them)."""
        if self.has_current:
            return ''
        missing = f'no motor currents were mapped: the bag holds no {self.currents_topic}'
        if self.has_joint_torque:
            return (
                f'\n  {missing}, so train refuses it for motor labels (the default); train with '
                '--target joint (its joint torques), or map the currents'
            )
        return (
            f'\n  {missing} and no joint torques, so train has no label in it: map the currents '
            '(for --target motor, the default) or the joint torques (for --target joint)'
        )

    def summary(self, max_positions: int = 5) -> str:
        """Counts, and the first ``max_positions`` positions of each kind of loss."""
        label = self.row_label

        def listed(items: Sequence[tuple[int, int] | int], kind: str) -> str:
            if not items:
                return ''
            shown = ', '.join(
                f'{item[0]}-{item[1]}' if isinstance(item, tuple) else str(item)
                for item in items[:max_positions]
            )
            more = ', ...' if len(items) > max_positions else ''
            return f'\n  {len(items)} {kind}: {label}s {shown}{more}'

        grid = self.grid or Gridded([], self.period_s, self.period_s, self.period_s)
        if self.method == 'snap':
            timing = (
                f'{grid.n_snapped} stamps snapped (max jitter {grid.max_jitter_s * 1e3:.3g} ms), '
                f'{grid.n_gaps} missing grid slots'
            )
        else:
            timing = (
                f'resampled from a median step of {grid.source_step_s * 1e3:.4g} ms (mean '
                f'{grid.mean_step_s * 1e3:.4g} ms), {grid.n_filled} grid points bridged over '
                f'{len(grid.holes)} holes'
            )
        velocities = (
            'from the mapped columns'
            if self.velocity_source == 'column'
            else 'differentiated from the positions'
        )
        return (
            f'{self.source} -> {self.out}: {self.n_rows_written} samples in '
            f'{self.n_segments} segment(s) from {self.n_rows_read} rows, '
            f'{len(self.dropped_rows)} rows dropped; period {self.period_s * 1e3:g} ms, '
            f'{timing}; velocities {velocities}'
            f'\n  {self.time_note()}'
            + self.label_note()
            + listed([row for row, _ in self.dropped_rows], 'rows dropped')
            + self._first_dropped()
            + listed([(a, b) for a, b, _ in grid.holes], 'holes bridged')
            + listed([(a, b) for a, b, _ in grid.breaks], 'pauses that end a segment')
            + listed([(a, b) for a, b, _ in grid.short], 'segments dropped as too short')
        )
