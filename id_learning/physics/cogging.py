"""Motor cogging, identified on the full band after the fit through the label filter.

Cogging is a torque ripple periodic in the motor angle, s sin(p N q) + c cos(p N q) per joint (p
periods per motor turn, N the gear ratio). Its frequency p N |v| / (2 pi) is tens of Hz, far
above the label filter's 0.3-1.2 Hz, so the fit through the filter cannot see it. Here it is fitted
on the training part's unfiltered labels less the identified model's torque on the controller's
inputs: the current noise is white, and the columns are noise-free functions of the position, so
least squares on the unfiltered labels is unbiased (a sample-wise fit also ignores that the
ripple aliases at the IPO rate). The columns are evaluated at the labels' time, q - d v, since the
labels lag the motion by the identified delay d.

Both the residual and the columns are high-passed alike (``HIGH_PASS_HZ``, zero phase, each
contiguous run of rows on its own): a linear filter on both sides keeps the fit unbiased, and it
removes what the model misfits below it (its fit through the filter pins only the label filter's
band; friction around reversals, the bodies' errors), which otherwise correlates with the ripple
by chance wherever the motor turns slowly: on a 50 s twin recording with a tenth of the default
noise, 0.5 N*m of the 6 N*m ripple of joint 2 unfiltered, 0.01 N*m high-passed at 10 Hz.

Per joint and candidate period, least squares of the residual on the sin and cos columns, on the
training part less its held-out tail (``confirmation.HELD_OUT_FRACTION``, the tail the claims
are judged on). The residual is not white (the misfit above the high-pass, the filter's own
colouring), so the amplitude's standard error is a sandwich over blocks of time longer than the
scores' correlation (cluster-robust), and the threshold of ``COGGING_Z`` standard errors is read
as its tail probability under Student's t with blocks - 1 degrees of freedom (stricter with few
blocks). Per joint, the most significant period whose amplitude passes and that lowers the
residual on the held-out tail is kept, at most one; its coefficients are then fitted on the
whole training part, with a 95 % interval from the same blocks.

Joint-torque labels (a sensor at the gear output) do not carry the motor's cogging: no stage.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import stats

from id_learning.dataset.blocks import block_ids, block_length_s
from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.signals import lowpass
from id_learning.physics.confirmation import HELD_OUT_FRACTION
from id_learning.physics.identified import IdentifiedPhysics, cogging_basis

__all__ = ['COGGING_Z', 'CoggingFit', 'fit_cogging', 'held_out_rows']

_LOG = logging.getLogger(__name__)

#: A period is kept where its amplitude reaches this many standard errors (as a normal tail
#: probability; with few blocks, the same probability under Student's t).
COGGING_Z = 5.0
#: The high-pass of the residual and the columns [Hz] (at most a quarter of the sample rate).
HIGH_PASS_HZ = 10.0
#: Runs of contiguous rows shorter than this many seconds are left out (too short to filter).
_MIN_RUN_S = 1.0
#: Fewer blocks of time than this in the fit part judge nothing (a sandwich over fewer is noise).
MIN_COGGING_BLOCKS = 10
#: The normal quantile of a two-sided 95 % interval.
_Z95 = float(stats.norm.ppf(0.975))


@dataclass(frozen=True)
class CoggingFit:
    """The cogging the full-band stage found.

    Attributes:
        coefficients: (n, 2) sine and cosine coefficients of p N q per joint [N*m] (zero: none).
        periods: (n,) periods p per motor turn (0: none).
        report: JSON-ready account per joint (``fit_cogging``).
    """

    coefficients: np.ndarray
    periods: np.ndarray
    report: dict[str, Any]


@dataclass(frozen=True)
class _Candidate:
    """One period's least squares on one joint's rows."""

    period: int
    beta: np.ndarray  # sine, cosine
    amplitude: float
    std: float  # the amplitude's standard error (blocks)
    blocks: int

    @property
    def z(self) -> float:
        """The amplitude in standard errors."""
        return self.amplitude / self.std if self.std > 0 else math.inf

    def threshold(self) -> float:
        """COGGING_Z's tail probability as a Student's t quantile with blocks - 1 dof."""
        return float(stats.t.isf(stats.norm.sf(COGGING_Z), self.blocks - 1))


def held_out_rows(dataset: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Training rows that fit, and each recording's held-out tail (``HELD_OUT_FRACTION``).

    The unfiltered labels need no gap between the two (no filter carries noise across).
    """
    rows = dataset.train_rows
    segments = dataset.extra.get('segments') or []
    ranges = [tuple(s['train']) for s in segments if 'train' in s]
    if not ranges:
        ranges = [(int(rows[0]), int(rows[-1]) + 1)]
    held = np.zeros(len(rows), dtype=bool)
    for start, stop in ranges:
        inside = rows[(rows >= start) & (rows < stop)]
        if len(inside):
            cut = inside[0] + (1.0 - HELD_OUT_FRACTION) * (inside[-1] - inside[0])
            held |= (rows >= cut) & (rows >= start) & (rows < stop)
    return rows[~held], rows[held]


@dataclass(frozen=True, eq=False)
class _Rows:
    """The training rows the stage reads, high-passed: the fit part first, then the held-out tail.

    Attributes:
        dataset: the recording.
        runs: the runs of rows filtered on their own.
        rows: (R,) the rows read, the fit part's ``n_fit`` first.
        n_fit: how many of ``rows`` fit; the rest are held out.
        residual: (R, n) the labels less the model's torque, high-passed [N*m].
        at_label: (N, n) q - d v, the positions at the labels' time [rad].
        cutoff_hz: the high-pass's cut-off [Hz].
    """

    dataset: Dataset
    runs: list[np.ndarray]
    rows: np.ndarray
    n_fit: int
    residual: np.ndarray
    at_label: np.ndarray
    cutoff_hz: float

    @classmethod
    def of(cls, dataset: Dataset, physics: IdentifiedPhysics) -> _Rows:
        """The training part less runs too short to filter (``_MIN_RUN_S``)."""
        fit, held = held_out_rows(dataset)
        if dataset.is_shuffled:
            # The training rows are scattered: each recording is high-passed whole, as its
            # labels were low-passed before the split.
            runs = dataset.recording_rows()
        else:
            shortest = _MIN_RUN_S / dataset.period_s
            runs = [run for run in (*_runs(fit), *_runs(held)) if len(run) >= shortest]
            kept = np.concatenate(runs) if runs else fit[:0]
            fit, held = np.intersect1d(fit, kept), np.intersect1d(held, kept)
        rows = np.concatenate([fit, held])
        cutoff = min(HIGH_PASS_HZ, 0.25 / dataset.period_s)
        residual, at_label = _residual(dataset, physics)
        residual = _high_passed(residual, runs, cutoff, dataset)[rows]
        return cls(dataset, runs, rows, len(fit), residual, at_label, cutoff)

    def columns(self, joint: int, gear_ratio: float, period: int) -> np.ndarray:
        """(R, 2) the joint's sin and cos of p N (q - d v), high-passed like the residual."""
        basis = cogging_basis(self.at_label[:, joint], gear_ratio, period)
        out: np.ndarray = _high_passed(basis, self.runs, self.cutoff_hz, self.dataset)[self.rows]
        return out

    @property
    def times(self) -> np.ndarray:
        """(R,) each row's time [s]."""
        out: np.ndarray = self.dataset.stamps_ns[self.rows] * 1e-9
        return out


def fit_cogging(
    dataset: Dataset, physics: IdentifiedPhysics, periods: tuple[int, ...]
) -> CoggingFit:
    """Find each joint's cogging ripple on the training part's unfiltered labels (module doc).

    Args:
        dataset: the recording; its training part is used, its test part never (under a
            shuffled split the high-pass runs over whole recordings, as the label filter did).
        physics: the model identified through the filter (its cogging is left out).
        periods: candidate periods p per motor turn.

    Returns:
        The ripples kept, and per joint what was found (or why nothing).
    """
    start = time.perf_counter()
    n = physics.robot.n_joints
    coefficients, kept = np.zeros((n, 2)), np.zeros(n, dtype=int)
    report: dict[str, Any] = {'periods_tried': list(periods), 'z_threshold': COGGING_Z,
                              'skipped': None, 'joints': []}  # fmt: skip
    if dataset.target != 'motor':
        report['skipped'] = 'joint-torque labels (a sensor at the gear output) carry no cogging'
        return CoggingFit(coefficients, kept, report)
    part = _Rows.of(dataset, physics)
    fit, held = slice(0, part.n_fit), slice(part.n_fit, len(part.rows))
    report |= {
        'high_pass_hz': part.cutoff_hz,
        'fit_s': part.n_fit * dataset.period_s,
        'held_out_s': (len(part.rows) - part.n_fit) * dataset.period_s,
    }
    if part.n_fit * dataset.period_s < MIN_COGGING_BLOCKS * _MIN_RUN_S:
        report['skipped'] = f'{report["fit_s"]:.1f} s of training rows to fit: too short'
        return CoggingFit(coefficients, kept, report)
    times, gear = part.times, physics.robot.drives.gear_ratio
    for j, joint in enumerate(physics.robot.joints):
        columns = {p: part.columns(j, gear[j], p) for p in periods}
        residual = part.residual[:, j]
        trials = [
            _least_squares(p, columns[p][fit], residual[fit], times[fit], dataset.period_s)
            for p in periods
        ]
        entry = {'joint': joint, **_judge(trials, columns, residual, held)}
        if entry['period']:
            p = entry['period']
            final = _least_squares(p, columns[p], residual, times, dataset.period_s)
            coefficients[j], kept[j] = final.beta, p
            entry |= _describe(final)
        report['joints'].append(entry)
    report['seconds'] = time.perf_counter() - start
    _LOG.info(
        'cogging on the full band: %s in %.1f s',
        ', '.join(f'{e["joint"]} p={e["period"]}' for e in report['joints'] if e['period'])
        or 'none significant',
        report['seconds'],
    )
    return CoggingFit(coefficients, kept, report)


def _residual(dataset: Dataset, physics: IdentifiedPhysics) -> tuple[np.ndarray, np.ndarray]:
    """The unfiltered labels less the model's torque (its cogging left out), and q - d v.

    On the controller's inputs, each (N, n) over the whole recording [N*m, rad]; under a
    contiguous split the rows outside the training part stay zero (never read).
    """
    n = physics.robot.n_joints
    model = replace(physics, cogging=np.zeros((n, 2)), cogging_periods=np.zeros(n, dtype=int))
    rows = np.arange(len(dataset.q)) if dataset.is_shuffled else dataset.train_rows
    motion = dataset.controller.take(rows)
    residual = np.zeros_like(dataset.tau_raw)
    residual[rows] = dataset.tau_raw[rows] - model.torque(motion.q, motion.v, motion.a)
    at_label = np.zeros_like(dataset.q)
    at_label[rows] = motion.q - physics.delay_s * motion.v
    return residual, at_label


def _runs(rows: np.ndarray) -> list[np.ndarray]:
    """The runs of contiguous rows in ``rows`` (sorted)."""
    breaks = np.flatnonzero(np.diff(rows) != 1) + 1
    return [run for run in np.split(rows, breaks) if len(run)]


def _high_passed(
    x: np.ndarray, runs: list[np.ndarray], cutoff_hz: float, dataset: Dataset
) -> np.ndarray:
    """The columns of x (N, k) less their zero-phase low-pass, each run of rows on its own."""
    out = np.zeros_like(x)
    cutoff = np.full(x.shape[1], cutoff_hz)
    for run in runs:
        out[run] = x[run] - lowpass(x[run], cutoff, dataset.period_s, dataset.filter_order)
    return out


def _least_squares(
    period: int, columns: np.ndarray, residual: np.ndarray, times: np.ndarray, period_s: float
) -> _Candidate:
    """The fit of ``residual`` on ``columns`` (N, 2), the amplitude's error from blocks."""
    gram = columns.T @ columns
    beta = np.linalg.solve(gram, columns.T @ residual)
    scores = columns * (residual - columns @ beta)[:, None]
    block_s = block_length_s(scores, period_s)
    ids = block_ids(times - times[0], block_s, period_s)
    count = int(ids.max()) + 1
    summed = np.zeros((count, columns.shape[1]))
    np.add.at(summed, ids, scores)
    inverse = np.linalg.inv(gram)
    covariance = inverse @ (summed.T @ summed) @ inverse * count / max(count - 1, 1)
    amplitude = float(np.hypot(beta[0], beta[1]))
    direction = beta / amplitude if amplitude > 0 else np.array([1.0, 0.0])
    std = math.sqrt(max(float(direction @ covariance @ direction), 0.0))
    return _Candidate(period, beta, amplitude, std, count)


def _judge(
    trials: list[_Candidate], columns: dict[int, np.ndarray], residual: np.ndarray, held: slice
) -> dict[str, Any]:
    """The most significant period that passes and lowers the held-out residual; or why none."""
    best = max(trials, key=lambda t: t.z)
    entry: dict[str, Any] = {
        'period': 0,
        'strongest': {'period': best.period, 'amplitude_nm': best.amplitude, 'z': best.z},
        'blocks': best.blocks,
    }
    if best.blocks < MIN_COGGING_BLOCKS:
        entry['why_none'] = (
            f'{best.blocks} blocks of time in the fit part, fewer than {MIN_COGGING_BLOCKS}: '
            'too short to judge'
        )
        return entry
    entry['why_none'] = f'no period reached {COGGING_Z:g} standard errors'
    for trial in sorted(trials, key=lambda t: -t.z):
        if trial.z < trial.threshold():
            break
        after = residual[held] - columns[trial.period][held] @ trial.beta
        power = float(np.mean(residual[held] ** 2)) if len(after) else 0.0
        gain = 1.0 - float(np.mean(after**2)) / power if power > 0 else 0.0
        if gain > 0.0:
            entry |= {'period': trial.period, 'z': trial.z, 'held_out_gain': gain}
            entry.pop('why_none')
            return entry
        entry['why_none'] = (
            f'p={trial.period} reached {trial.z:.1f} standard errors but did not lower the '
            f'held-out residual (gain {gain:.2g})'
        )
    return entry


def _describe(final: _Candidate) -> dict[str, Any]:
    """Amplitude with its 95 % interval, and the phase, of the fit on the training part."""
    low = max(final.amplitude - _Z95 * final.std, 0.0)
    return {
        'amplitude_nm': final.amplitude,
        'amplitude_ci95_nm': [low, final.amplitude + _Z95 * final.std],
        'sine_nm': float(final.beta[0]),
        'cosine_nm': float(final.beta[1]),
        'phase_rad': math.atan2(float(final.beta[1]), float(final.beta[0])),
    }
