"""The accelerations a controller sends along a recorded motion, against the robot's limits.

The predictor refuses a sample whose acceleration exceeds ``ACCELERATION_FACTOR`` x its limit
(``plausibility.SampleGate``), and the replay refuses a bag whose reference does. The reference
is the controller's inputs (``InputDefinition.controller``): recorded velocities smoothed at the
robot's ``input_smoothing_hz``, differentiated. So the doors that read a recording before it
goes online judge the same accelerations: ``load_recording`` (train, evaluate, diagnose) refuses
them, as it refuses velocities beyond their bound, and ``inspect`` lists them.

The accelerations are taken on each stretch of the motion on its own: a gap of more than
``GAP_PERIODS`` IPO periods, a non-finite row or a stamp that does not increase ends a
stretch (differences across them say nothing about the arm); a stretch too short for the
smoothing filter is not judged.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from id_learning.dataset.consistency import gap_starts
from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.plausibility import ACCELERATION_FACTOR, check_accelerations
from id_learning.errors import DatasetError
from id_learning.robot.config import RobotConfig

__all__ = [
    'GAP_PERIODS',
    'AccelerationExcess',
    'acceleration_excess',
    'check_controller_accelerations',
    'controller_accelerations',
]

#: A silence longer than this many IPO periods ends a stretch (as ``inspect`` counts gaps).
GAP_PERIODS = 1.5

#: What the accelerations are, for messages.
WHAT = 'the accelerations a controller sends along this motion'


def controller_accelerations(
    robot: RobotConfig, stamps_ns: np.ndarray, q: np.ndarray, v: np.ndarray
) -> np.ndarray:
    """(N, n) the controller inputs' accelerations [rad/s^2], columns in the robot's order.

    NaN on rows that are not judged: non-finite rows and stretches too short for the filter.

    Args:
        robot: its ``input_smoothing_hz`` and IPO period make the inputs.
        stamps_ns: (N,) sample stamps [ns].
        q, v: (N, n) positions [rad] and velocities [rad/s] in ``robot.joints`` order.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
    out = np.full(v.shape, np.nan)
    if len(stamps) < 2:
        return out
    bad = ~(np.isfinite(q).all(axis=1) & np.isfinite(v).all(axis=1))
    bad[1:] |= np.diff(stamps) <= 0
    rows = np.flatnonzero(bad)
    starts = {*gap_starts(stamps, robot.ipo_period_s, GAP_PERIODS), *rows, *(rows + 1)}
    bounds = sorted(starts | {len(stamps)})
    inputs = InputDefinition.controller(robot.input_smoothing_hz)
    for a, b in itertools.pairwise(bounds):
        if b <= a or bad[a]:  # a bad row is a stretch of its own (its stamp may be the cause)
            continue
        try:
            out[a:b] = inputs.motion(q[a:b], v[a:b], robot.ipo_period_s).a
        except DatasetError:
            continue  # too short for the smoothing filter: not judged
    return out


def check_controller_accelerations(
    robot: RobotConfig, stamps_ns: np.ndarray, q: np.ndarray, v: np.ndarray, *, where: str
) -> None:
    """Refuse a motion whose controller accelerations exceed ``ACCELERATION_FACTOR`` x limits.

    Raises:
        DatasetError: the first such sample, naming where, sample, stamp, joint and value, what
            the accelerations are, and who refuses them online.
    """
    a = controller_accelerations(robot, stamps_ns, q, v)
    try:
        check_accelerations(
            robot.joints,
            np.asarray(stamps_ns),
            np.nan_to_num(a, nan=0.0),
            limits=robot.limits,
            where=where,
        )
    except DatasetError as err:
        raise DatasetError(
            f'{err}; the predictor rejects such samples and the replay such a bag ({WHAT}: '
            f'velocities smoothed at input_smoothing_hz {_hz(robot)} Hz, differentiated)'
        ) from None


@dataclass(frozen=True)
class AccelerationExcess:
    """One joint's controller accelerations beyond ``ACCELERATION_FACTOR`` x its limit.

    Attributes:
        share: the share of the judged samples beyond [-].
        first_sample: the first of them (index on its topic) and first_stamp_ns its stamp [ns].
        peak: the largest |acceleration| [rad/s^2]; limit: the joint's limit [rad/s^2].
    """

    share: float
    first_sample: int
    first_stamp_ns: int
    peak: float
    limit: float

    def describe(self, topic: str, joint: str) -> str:
        """The inspect problem line."""
        return (
            f'{topic}: {joint} acceleration beyond {ACCELERATION_FACTOR:g} x its limit '
            f'{self.limit:.4g} rad/s^2 in {100 * self.share:.2f} % of samples, the first at '
            f'sample {self.first_sample} (stamp {self.first_stamp_ns} ns), up to '
            f'{self.peak:.4g} rad/s^2 (the controller inputs: velocities smoothed at '
            'input_smoothing_hz, differentiated); the predictor rejects such samples, train and '
            "the replay refuse the bag: check the robot config's limits.acceleration"
        )


def acceleration_excess(
    robot: RobotConfig, stamps_ns: np.ndarray, a: np.ndarray
) -> tuple[AccelerationExcess | None, ...]:
    """Per robot joint, its accelerations beyond the gate (``controller_accelerations``'s a)."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    judged = np.isfinite(a)
    bound = ACCELERATION_FACTOR * robot.limits.acceleration
    beyond = np.abs(np.where(judged, a, 0.0)) > bound
    out: list[AccelerationExcess | None] = []
    for j in range(len(robot.joints)):
        if not beyond[:, j].any():
            out.append(None)
            continue
        first = int(np.argmax(beyond[:, j]))
        out.append(
            AccelerationExcess(
                share=float(beyond[:, j].sum() / max(int(judged[:, j].sum()), 1)),
                first_sample=first,
                first_stamp_ns=int(stamps[first]),
                peak=float(np.max(np.abs(a[judged[:, j], j]))),
                limit=float(robot.limits.acceleration[j]),
            )
        )
    return tuple(out)


def _hz(robot: RobotConfig) -> str:
    unique = sorted({float(x) for x in robot.input_smoothing_hz})
    return f'{unique[0]:g}' if len(unique) == 1 else '/'.join(f'{x:g}' for x in unique)
