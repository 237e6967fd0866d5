"""A recording as aligned arrays, read from and written to the bag contract.

The bag contract: ``/joint_states`` (sensor_msgs/JointState: name, position [rad], velocity
[rad/s], effort = measured joint torque [N*m] or empty) and ``/motor_currents``
(sensor_msgs/JointState whose effort holds motor currents [A]), with the same joint names and the
same header stamps sample by sample. Topic names come from the robot config.

A bag may hold several segments (an import of several files, or of a log with long pauses): the
stamps of their first samples are listed in ``metadata.yaml``'s ``custom_data`` under
``SEGMENTS_KEY`` (a JSON list). Stamps may jump between segments; within one they keep the IPO
grid. Preprocessing and the split treat each segment as a recording of its own.
"""

from __future__ import annotations

import itertools
import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from id_learning.bag import (
    JOINT_STATE,
    BagWriter,
    JointStateSeries,
    bag_custom_data,
    encode_joint_state,
    read_joint_states,
)
from id_learning.dataset.accelerations import check_controller_accelerations
from id_learning.dataset.consistency import KinematicConsistency
from id_learning.dataset.content import GravityTorque, check_content
from id_learning.dataset.plausibility import (
    PAIRING_SHARE,
    check_efforts,
    check_finite,
    check_limits,
    check_stamps,
    first_unpaired,
)
from id_learning.errors import DatasetError
from id_learning.robot.config import RobotConfig, TopicConfig
from id_learning.robot.drives import amperes_per_newton_metre

_LOG = logging.getLogger(__name__)

__all__ = [
    'SEGMENTS_KEY',
    'Recording',
    'check_finite',
    'check_recording_content',
    'check_stamps',
    'joint_name_mismatch',
    'load_recording',
    'write_recording',
]

#: The ``custom_data`` key of the segments' first stamps [ns] (a JSON list).
SEGMENTS_KEY = 'id_learning.segment_starts_ns'


@dataclass(frozen=True, eq=False)
class Recording:
    """Synchronised samples of one recording, in ``joints`` order.

    Attributes:
        joints: joint names, the column order of every array.
        stamps_ns: (N,) header stamps [ns since epoch], strictly increasing.
        position: (N, n) joint positions [rad].
        velocity: (N, n) joint velocities [rad/s].
        current: (N, n) motor currents [A], or None when the recording has none.
        joint_torque: (N, n) measured joint torques [N*m], or None when not measured.
        source: where the samples came from (bag path, log file), for error messages.
        segment_starts: first sample of each segment, from 0 (see the module docstring).
        content_warnings: what ``load_recording``'s content check warned of (a joint that does
            not move, a clipped label), for reports.
    """

    joints: tuple[str, ...]
    stamps_ns: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    current: np.ndarray | None = None
    joint_torque: np.ndarray | None = None
    source: str = '<memory>'
    segment_starts: tuple[int, ...] = (0,)
    content_warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        """Check that every array has one row per stamp and one column per joint."""
        n_samples, n_joints = len(self.stamps_ns), len(self.joints)
        starts = self.segment_starts
        if (
            not starts
            or starts[0] != 0
            or any(b <= a for a, b in zip(starts, (*starts[1:], max(n_samples, 1)), strict=True))
        ):
            raise DatasetError(
                f'{self.source}: segment starts {list(starts)} must rise from 0 within the '
                f'{n_samples} samples'
            )
        for key in ('position', 'velocity', 'current', 'joint_torque'):
            array = getattr(self, key)
            if array is not None and array.shape != (n_samples, n_joints):
                raise DatasetError(
                    f'{self.source}: {key} has shape {array.shape}, '
                    f'expected ({n_samples}, {n_joints})'
                )

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return len(self.stamps_ns)

    def segments(self) -> list[Recording]:
        """The segments as recordings of their own (this recording when it has one)."""
        if len(self.segment_starts) == 1:
            return [self]
        bounds = (*self.segment_starts, self.n_samples)
        count = len(self.segment_starts)

        def part(array: np.ndarray | None, a: int, b: int) -> np.ndarray | None:
            return None if array is None else array[a:b]

        return [
            Recording(
                joints=self.joints,
                stamps_ns=self.stamps_ns[a:b],
                position=self.position[a:b],
                velocity=self.velocity[a:b],
                current=part(self.current, a, b),
                joint_torque=part(self.joint_torque, a, b),
                source=f'{self.source} (segment {k + 1} of {count})',
            )
            for k, (a, b) in enumerate(itertools.pairwise(bounds))
        ]

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9 if self.n_samples else 0.0

    def select(self, index: slice | np.ndarray) -> Recording:
        """Return the samples at ``index`` as a new recording."""

        def pick(array: np.ndarray | None) -> np.ndarray | None:
            return None if array is None else array[index]

        return Recording(
            joints=self.joints,
            stamps_ns=self.stamps_ns[index],
            position=self.position[index],
            velocity=self.velocity[index],
            current=pick(self.current),
            joint_torque=pick(self.joint_torque),
            source=self.source,
        )


def write_recording(
    recording: Recording,
    path: Path | str,
    topics: TopicConfig | None = None,
    *,
    overwrite: bool = False,
) -> Path:
    """Write a recording as a bag in the contract; header stamp = log time = ``stamps_ns``."""
    topics = topics or TopicConfig()
    path = Path(path)
    empty = np.empty(0)
    custom = {}
    if len(recording.segment_starts) > 1:
        starts = recording.stamps_ns[list(recording.segment_starts)]
        custom[SEGMENTS_KEY] = json.dumps([int(stamp) for stamp in starts])
    with BagWriter(path, overwrite=overwrite, custom_data=custom) as writer:
        writer.add_topic(topics.joint_states, JOINT_STATE)
        if recording.current is not None:
            writer.add_topic(topics.motor_currents, JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            effort = empty if recording.joint_torque is None else recording.joint_torque[k]
            writer.write(
                topics.joint_states,
                stamp,
                encode_joint_state(
                    stamp, recording.joints, recording.position[k], recording.velocity[k], effort
                ),
            )
            if recording.current is not None:
                writer.write(
                    topics.motor_currents,
                    stamp,
                    encode_joint_state(
                        stamp, recording.joints, empty, empty, recording.current[k]
                    ),
                )
    return path


def joint_name_mismatch(names: Sequence[str], expected: Sequence[str]) -> str | None:
    """How ``names`` differ from ``expected``, in the words of ``load_recording``'s refusal.

    'missing [...], unexpected [...]', with ', repeated [...]' for joints named more than once;
    None when both name the same joints once each (the order does not matter: it is fixed up).
    """
    missing = [name for name in expected if name not in names]
    unexpected = [name for name in names if name not in expected]
    repeated = list(dict.fromkeys(name for name in names if list(names).count(name) > 1))
    if not (missing or unexpected or repeated):
        return None
    return f'missing {missing}, unexpected {unexpected}' + (
        f', repeated {repeated}' if repeated else ''
    )


def _reorder(series: JointStateSeries, joints: tuple[str, ...], where: str) -> np.ndarray:
    """Column permutation that puts a topic's joints in config order (by name)."""
    mismatch = joint_name_mismatch(series.names, joints)
    if mismatch is not None:
        raise DatasetError(
            f'{where}: joint names {list(series.names)} '
            f'do not match the robot config {list(joints)} ({mismatch})'
        )
    return np.array([series.names.index(name) for name in joints])


def load_recording(
    path: Path | str,
    robot: RobotConfig,
    *,
    max_gap_periods: float = 3.0,
    require_current: bool = True,
    progress: bool = False,
    trim_unpaired_tail: bool = False,
    gravity: GravityTorque | None = None,
) -> Recording:
    """Read a bag in the contract into a Recording, validated and in the robot's joint order.

    Joint columns are reordered by name when only the order differs. A torn recording may end
    with messages on one topic that have no partner on the other: they are refused unless
    ``trim_unpaired_tail`` is set, in which case they are dropped with a warning. ``gravity``:
    the robot's, for the content check's sign (``content.sign_findings``).

    Raises:
        BagError: missing topic, wrong type, truncated or corrupt file.
        DatasetError: joint names differ, NaN/Inf samples (in the joint states' effort only
            when it is the label: with ``require_current`` it is left out with a warning),
            stamps backwards/repeated/gapped, positions or velocities beyond the robot's limits,
            currents or joint torques beyond what its torque limits need, or the two topics'
            stamps do not match (each names topic, joint and sample; ``dataset.plausibility``);
            a label (currents, else joint torques) constant in every sample, or no joint moving
            (``dataset.content``, which also warns of a still joint or a clipped label).
    """
    path = Path(path)
    topics = robot.topics
    states = read_joint_states(path, topics.joint_states, progress=progress)
    where_js = f'{path}: {topics.joint_states}'
    order = _reorder(states, robot.joints, where_js)
    if states.position is None or states.velocity is None:
        raise DatasetError(
            f'{where_js}: messages carry no '
            f'{"position" if states.position is None else "velocity"}'
        )
    starts = _segment_starts(path, states.stamps_ns)
    _check_segment_stamps(states.stamps_ns, starts, robot, max_gap_periods, where_js)
    position = states.position[:, order]
    velocity = states.velocity[:, order]
    joint_torque = None if states.effort is None else states.effort[:, order]
    check_finite(position, robot.joints, states.stamps_ns, f'{where_js} position')
    check_finite(velocity, robot.joints, states.stamps_ns, f'{where_js} velocity')
    if require_current and joint_torque is not None and not np.isfinite(joint_torque).all():
        # Not the label here (the currents are): many drivers fill effort with NaN when the arm
        # has no torque sensors. Left out, so nothing downstream reads it.
        _LOG.warning(
            '%s effort: %d of %d values are not finite; left out (the currents are the label)',
            where_js,
            int((~np.isfinite(joint_torque)).sum()),
            joint_torque.size,
        )
        joint_torque = None
    if joint_torque is not None:
        check_finite(joint_torque, robot.joints, states.stamps_ns, f'{where_js} effort')
        check_efforts(
            robot.joints,
            states.stamps_ns,
            joint_torque,
            torque_limit=robot.limits.torque,
            where=f'{where_js} effort',
            what='joint torque [N*m]',
        )
    _check_motion(robot, states.stamps_ns, position, velocity, where=where_js, starts=starts)

    current = None
    if require_current:
        currents = read_joint_states(
            path, topics.motor_currents, progress=progress, fields=('effort',)
        )
        where_mc = f'{path}: {topics.motor_currents}'
        order_mc = _reorder(currents, robot.joints, where_mc)
        if currents.effort is None:
            raise DatasetError(f'{where_mc}: messages carry no effort (the motor currents)')
        _check_segment_stamps(currents.stamps_ns, starts, robot, max_gap_periods, where_mc)
        size = min(len(currents.stamps_ns), len(states.stamps_ns))
        _check_paired(states.stamps_ns, currents.stamps_ns, robot.ipo_period_s, path, topics)
        if len(currents.stamps_ns) != len(states.stamps_ns):
            longer = topics.joint_states if len(states.stamps_ns) > size else topics.motor_currents
            extra = abs(len(states.stamps_ns) - len(currents.stamps_ns))
            if not trim_unpaired_tail:
                raise DatasetError(
                    f'{path}: the last {extra} message(s) of {longer} have no partner on the '
                    f'other topic (samples {size} on), as a torn recording leaves them; pass '
                    '--trim-unpaired-tail (train, sweep, diagnose; trim_unpaired_tail in '
                    'load_recording) to drop them'
                )
            _LOG.warning('%s: dropped the last %d unpaired message(s) of %s', path, extra, longer)
            states = replace(
                states,
                stamps_ns=states.stamps_ns[:size],
                log_ns=states.log_ns[:size],
            )
            position, velocity = position[:size], velocity[:size]
            joint_torque = None if joint_torque is None else joint_torque[:size]
        current = currents.effort[:size, order_mc]
        check_finite(current, robot.joints, currents.stamps_ns[:size], f'{where_mc} effort')
        drives = robot.drives
        check_efforts(
            robot.joints,
            currents.stamps_ns[:size],
            current,
            torque_limit=robot.limits.torque,
            where=f'{where_mc} effort',
            what='current [A]',
            unit_per_nm=amperes_per_newton_metre(drives),
        )
    recording = Recording(
        joints=robot.joints,
        stamps_ns=states.stamps_ns,
        position=position,
        velocity=velocity,
        current=current,
        joint_torque=joint_torque,
        source=str(path),
        segment_starts=tuple(start for start in starts if start < len(states.stamps_ns)),
    )
    held = None if gravity is None else (robot, gravity)
    return replace(recording, content_warnings=check_recording_content(recording, held_by=held))


def _check_paired(
    states_ns: np.ndarray,
    currents_ns: np.ndarray,
    period_s: float,
    path: Path,
    topics: TopicConfig,
) -> None:
    """Require one current message per joint state, stamped alike (``PAIRING_SHARE``).

    Raises:
        DatasetError: names the first sample whose stamps differ by more, and by how much.
    """
    sample = first_unpaired(states_ns, currents_ns, period_s)
    if sample is not None:
        apart_us = (int(currents_ns[sample]) - int(states_ns[sample])) * 1e-3
        raise DatasetError(
            f'{path}: {topics.motor_currents} and {topics.joint_states} stamps differ by '
            f'{apart_us:.1f} us at sample {sample}, more than the '
            f'{PAIRING_SHARE * period_s * 1e6:.0f} us ({PAIRING_SHARE:.0%} of the IPO period) '
            'that pairs them; the bag contract requires one current message per joint state '
            'with (nearly) the same header stamp'
        )
    size = min(len(states_ns), len(currents_ns))
    offset_ns = np.abs(currents_ns[:size].astype(np.int64) - states_ns[:size].astype(np.int64))
    if size and offset_ns.max() > 0:
        _LOG.info(
            '%s: currents stamped up to %.1f us off the joint states; paired sample by sample '
            '(the joint states give the time)',
            path,
            float(offset_ns.max()) * 1e-3,
        )


def check_recording_content(
    recording: Recording,
    target: str | None = None,
    *,
    warn: bool = True,
    held_by: tuple[RobotConfig, GravityTorque] | None = None,
) -> tuple[str, ...]:
    """``content.check_content`` of a recording: its positions and its label.

    Args:
        target: 'motor' (the currents are the label), 'joint' (the measured joint torques), or
            None: the currents when the recording has them, else the joint torques.
        warn: log the warnings (they are returned either way).
        held_by: the robot and its gravity torque, for ``check_content``'s sign check.

    Raises:
        DatasetError: the label is constant in every sample of a joint, or no joint moves.
    """
    if target == 'motor' or (target is None and recording.current is not None):
        label, quantity, unit = recording.current, 'motor current', 'A'
    else:
        label, quantity, unit = recording.joint_torque, 'joint torque', 'N*m'
    return check_content(
        recording.position,
        label,
        recording.joints,
        where=recording.source,
        quantity=quantity,
        unit=unit,
        duration_s=recording.duration_s,
        warn=warn,
        held_by=held_by,
    )


def _check_motion(
    robot: RobotConfig,
    stamps_ns: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    *,
    where: str,
    starts: tuple[int, ...],
) -> None:
    """Limits (the URDF's name a narrow config), consistency, the predictor's acceleration gate."""
    check_limits(
        robot.joints,
        stamps_ns,
        position,
        velocity,
        limits=robot.limits,
        where=where,
        urdf=robot.urdf_path,
    )
    KinematicConsistency.for_robot(robot).check(
        stamps_ns, position, velocity, where=where, starts=starts
    )
    check_controller_accelerations(robot, stamps_ns, position, velocity, where=where)


def _segment_starts(path: Path, stamps_ns: np.ndarray) -> tuple[int, ...]:
    """First sample of each segment the bag's metadata lists (``SEGMENTS_KEY``), else (0,).

    Raises:
        DatasetError: the entry is malformed, or names a stamp the recording does not have.
    """
    text = bag_custom_data(path).get(SEGMENTS_KEY)
    if text is None:
        return (0,)
    try:
        stamps = [int(stamp) for stamp in json.loads(text)]
    except (ValueError, TypeError) as err:
        raise DatasetError(
            f'{path}: metadata.yaml custom_data {SEGMENTS_KEY} is no list of stamps: {err}'
        ) from err
    index = np.searchsorted(stamps_ns, stamps)
    missing = [
        stamp
        for stamp, i in zip(stamps, index, strict=True)
        if i >= len(stamps_ns) or stamps_ns[i] != stamp
    ]
    if missing or not stamps or index[0] != 0:
        raise DatasetError(
            f'{path}: metadata.yaml custom_data {SEGMENTS_KEY} lists segment starts the '
            f'recording does not begin with or hold (e.g. {missing[:3] or stamps[:1]} ns)'
        )
    return tuple(int(i) for i in index)


def _check_segment_stamps(
    stamps_ns: np.ndarray,
    starts: tuple[int, ...],
    robot: RobotConfig,
    max_gap_periods: float,
    where: str,
) -> None:
    """``check_stamps`` within each segment, and increasing stamps across their seams."""
    check_stamps(stamps_ns, robot.ipo_period_s, np.inf, where)
    bounds = (*starts, len(stamps_ns))
    for k, (a, b) in enumerate(itertools.pairwise(bounds)):
        segment = where if len(starts) == 1 else f'{where} (segment {k + 1}, from sample {a})'
        check_stamps(stamps_ns[a:b], robot.ipo_period_s, max_gap_periods, segment)
