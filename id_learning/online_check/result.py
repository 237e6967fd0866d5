"""The online check's result: what it measured, as JSON and as a terminal summary.

Kept apart from the check itself (``online_check``) so that the numbers and their presentation
can be read, tested and reused without the ROS machinery that produces them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.errors import IdLearningError

__all__ = ['NS_PER_S', 'OnlineCheckError', 'OnlineCheckResult']

NS_PER_S = 1_000_000_000


class OnlineCheckError(IdLearningError):
    """A node failed to start or to finish, or the check produced no comparable sample."""


@dataclass(frozen=True, eq=False)
class OnlineCheckResult:
    """What the online check measured; arrays are (n,) per joint in ``joints`` order.

    Attributes:
        kind: the artifact's model kind.
        artifact, bag: what was checked.
        joints: joint names.
        test_start_s, test_s: start (from the bag's first sample) and length of the test part [s].
        excerpt_start_s, excerpt_s: start and length of the replayed excerpt [s].
        is_clipped: the test part is shorter than the requested excerpt.
        n_samples: samples in the excerpt.
        n_inputs: reference messages the listener received.
        n_outputs: tau_u messages received that belong to an excerpt sample.
        n_missing: excerpt samples without tau_u.
        rmse_online_nm: online tau_u against the label, through the label filter [N*m].
        rmse_offline_nm: offline prediction (controller inputs) against the label, through the
            filter, same samples.
        max_abs_online_offline_nm: max |online - offline| [N*m].
        max_abs_node_error_nm: max |online - the artifact on the received references| [N*m].
        max_input_diff: max |reference - dataset input| per 'q' [rad], 'v' [rad/s], 'a' [rad/s^2].
        predictor: the predictor's last /diagnostics (latency and compute in ms, counts).
        replay: the replay's last /diagnostics (lateness in ms, cycles).
        notes: what the reader should know (clipping, a bag the model was not trained on).
        wall_s: duration of the whole call [s].
    """

    kind: str
    artifact: Path
    bag: Path
    joints: tuple[str, ...]
    test_start_s: float
    test_s: float
    excerpt_start_s: float
    excerpt_s: float
    is_clipped: bool
    n_samples: int
    n_inputs: int
    n_outputs: int
    n_missing: int
    rmse_online_nm: np.ndarray
    rmse_offline_nm: np.ndarray
    max_abs_online_offline_nm: np.ndarray
    max_abs_node_error_nm: np.ndarray
    max_input_diff: dict[str, np.ndarray]
    predictor: dict[str, str]
    replay: dict[str, str]
    notes: tuple[str, ...] = ()
    wall_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (arrays as lists)."""
        out: dict[str, Any] = {}
        for name, value in self.__dict__.items():
            if isinstance(value, dict):
                out[name] = {key: _jsonable(item) for key, item in value.items()}
            else:
                out[name] = _jsonable(value)
        return out

    def summary(self) -> str:
        """A few lines for the terminal: counts, RMSE table, input differences, latency."""
        pred = self.predictor

        def ms(key: str) -> str:
            return f'{float(pred.get(key, "nan")):.3f}'

        width = max(10, *(len(j) + 2 for j in self.joints))
        header = ''.join(f'{j:>{width}}' for j in self.joints)

        def row(label: str, values: np.ndarray) -> str:
            return f'  {label:<38}' + ''.join(f'{x:>{width}.4g}' for x in values)

        clip = ' (clipped: the test part is shorter)' if self.is_clipped else ''
        lines = [
            f'online check of {self.kind} on {self.bag}: replayed {self.excerpt_s:.1f} s of the '
            f'test part ({self.test_start_s:.1f} s to {self.test_start_s + self.test_s:.1f} s of '
            f'the bag) from {self.excerpt_start_s:.1f} s in real time{clip}',
            f'  {self.n_samples} samples, {self.n_inputs} reference inputs, {self.n_outputs} '
            f'tau_u outputs, {self.n_missing} missing; {pred.get("clamped_samples", "?")} '
            f'clamped, {pred.get("out_of_range_samples", "?")} out of the training range, '
            f'{pred.get("rejected", "?")} rejected',
            f'  {"[N*m]":<38}{header}',
            row('RMSE online vs label, through filter', self.rmse_online_nm),
            row('RMSE offline vs label, through filter', self.rmse_offline_nm),
            row('max |online - offline|', self.max_abs_online_offline_nm),
            row('max |node - model(its inputs)|', self.max_abs_node_error_nm),
            '  online inputs vs offline inputs (replay reference vs training preprocessing): '
            + ', '.join(
                f'max |d{name}| {float(np.max(diff)):.3g} {unit}'
                for (name, diff), unit in zip(
                    self.max_input_diff.items(), ('rad', 'rad/s', 'rad/s^2'), strict=True
                )
            ),
            f'  predictor latency [ms]: receive-to-publish median {ms("latency_median_ms")}, '
            f'p99 {ms("latency_p99_ms")}, max {ms("latency_max_ms")}; compute median '
            f'{ms("compute_median_ms")}, p99 {ms("compute_p99_ms")}, max {ms("compute_max_ms")}'
            f' ({pred.get("latency_samples", "?")} samples)',
        ]
        if self.replay:
            rep = self.replay
            lines.append(
                f'  replay lateness [ms]: median {float(rep.get("lateness_median_ms", "nan")):.3f}'
                f', p99 {float(rep.get("lateness_p99_ms", "nan")):.3f}, max '
                f'{float(rep.get("lateness_max_ms", "nan")):.3f}; '
                f'{rep.get("late_cycles", "?")} cycles later than one period'
            )
        lines += [f'  note: {note}' for note in self.notes]
        lines.append(f'  ({self.wall_s:.1f} s)')
        return '\n'.join(lines)


def _jsonable(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return list(value)
    return value
