"""Standstills: where a joint rests, the torque its friction holds is not a function of motion.

Friction at rest takes whatever value between its static levels the approach and the
controller's integrator leave; a model of friction as a function of velocity cannot say which
(and a measured velocity at rest is sensor noise, so the sign of any friction column there is
noise too). The diagnosis therefore gives each standstill of each joint a free held torque: a
box over the standstill, filtered like the label, projected out of the residual and of every
candidate's columns (Frisch-Waugh-Lovell, so every fit behaves as if these nuisance columns were
in it). What the held torque was is then never blamed on an effect. Only the training part is
projected for selection: the held-out part is judged as a model would predict it, held torques
and all. Once the effects are chosen their values are read from both parts, the held-out part
projected off its own standstills alike (``project(x, 'test')``).
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.linalg import block_diag

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.signals import butterworth

__all__ = ['StandstillProjection', 'standstill_intervals']


def standstill_intervals(
    v: np.ndarray, period_s: float, threshold: float, min_s: float
) -> list[tuple[int, int]]:
    """(start, stop) sample ranges where |v| stays below ``threshold`` for at least ``min_s``."""
    still = np.abs(np.asarray(v, dtype=float)) < threshold
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    shortest = max(1, round(min_s / period_s))
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= shortest]


class StandstillProjection:
    """Per part and joint, an orthonormal basis of the standstill boxes on the part's rows.

    Args:
        recordings: per recording, its dataset and its kept rows per part ('train', 'test').
        threshold: |v| [rad/s] of the fitting inputs below which a joint rests.
        min_s: shortest rest [s].
    """

    def __init__(
        self,
        recordings: list[tuple[Dataset, dict[str, np.ndarray]]],
        threshold: float,
        min_s: float,
    ) -> None:
        n = recordings[0][0].q.shape[1] if recordings else 0
        # A rest in one part leaks only the filter's tail into the other's rows: a box belongs
        # to the part that holds most of its (filtered) energy.
        per_recording = [
            [_split(box, rows['train'], rows['test']) for box in _boxes(dataset, threshold, min_s)]
            for dataset, rows in recordings
        ]
        #: part -> rests found per joint, over all recordings.
        self.counts = {
            part: np.array(
                [sum(cols[j][part].shape[1] for cols in per_recording) for j in range(n)],
                dtype=int,
            )
            for part in ('train', 'test')
        }
        #: part -> per joint, the basis over that part's rows (None: no rest).
        self.bases: dict[str, list[np.ndarray | None]] = {
            part: [
                _orthonormal(block_diag(*[cols[j][part] for cols in per_recording]))
                for j in range(n)
            ]
            for part in ('train', 'test')
        }

    def project(self, x: np.ndarray, part: str = 'train') -> np.ndarray:
        """A part's values (M, n) or columns (M, n, k) without their share along its boxes."""
        out = np.array(x, dtype=float, copy=True)
        for j, basis in enumerate(self.bases[part]):
            if basis is not None:
                out[:, j] = out[:, j] - basis @ (basis.T @ out[:, j])
        return out


def _boxes(dataset: Dataset, threshold: float, min_s: float) -> list[np.ndarray]:
    """Per joint, (N, m) the filtered boxes over the joint's standstills in one dataset."""
    n_samples, n = dataset.v.shape
    out = []
    for j in range(n):
        sos = butterworth(float(dataset.cutoff_hz[j]), dataset.period_s, dataset.filter_order)
        cols = []
        for rows in dataset.recording_rows():
            for start, stop in standstill_intervals(
                dataset.v[rows, j], dataset.period_s, threshold, min_s
            ):
                box = np.zeros(len(rows))
                box[start:stop] = 1.0
                column = np.zeros(n_samples)
                column[rows] = signal.sosfiltfilt(sos, box)
                cols.append(column)
        out.append(np.column_stack(cols) if cols else np.zeros((n_samples, 0)))
    return out


def _split(boxes: np.ndarray, train: np.ndarray, test: np.ndarray) -> dict[str, np.ndarray]:
    """Part -> the boxes (N, m) on its rows that hold most of their energy there.

    The rows of both parts are sampled alike, so their energies compare.
    """
    on = {'train': boxes[train], 'test': boxes[test]}
    energy = {part: np.sum(x**2, axis=0) for part, x in on.items()}
    mostly_train = energy['train'] >= 0.5 * (energy['train'] + energy['test'])
    return {
        'train': on['train'][:, mostly_train & (energy['train'] > 0)],
        'test': on['test'][:, ~mostly_train & (energy['test'] > 0)],
    }


def _orthonormal(x: np.ndarray) -> np.ndarray | None:
    """An orthonormal basis of x's column space (numerically null columns dropped)."""
    if x.shape[1] == 0 or x.shape[0] == 0:
        return None
    u, s, _ = np.linalg.svd(x, full_matrices=False)
    keep = s > 1e-8 * max(float(s[0]), 1e-300)
    return u[:, keep] if np.any(keep) else None
