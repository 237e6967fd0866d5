"""The report types of ``inspect_bag`` and the findings they list as problems.

Kept apart from the analysis (``inspect.py``), the text rendering (``inspect_text.py``) and the
plot (``inspect_plot.py``), which all read these types; this module imports none of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from id_learning.bag import JOINT_STATE, JointStateSeries
from id_learning.dataset.accelerations import AccelerationExcess
from id_learning.dataset.plausibility import SCALE_PEAK_FACTOR, TORQUE_FACTOR
from id_learning.dataset.recording import joint_name_mismatch
from id_learning.errors import BagError

__all__ = [
    'FIELDS',
    'GAP_PERIODS',
    'MAX_LISTED',
    'BagReport',
    'ContractReport',
    'FieldStats',
    'Gap',
    'JointReport',
    'TimingReport',
    'TopicReport',
]

GAP_PERIODS = 1.5
"""A step longer than this many nominal periods is a gap."""
MAX_LISTED = 10
"""How many gaps, repeated and backward stamps a report lists (it counts all of them)."""
FIELDS = ('position', 'velocity', 'effort')


@dataclass(frozen=True)
class Gap:
    """A step between two samples longer than ``GAP_PERIODS`` nominal periods.

    Attributes:
        sample: index of the first sample after the gap, on its topic.
        stamp_ns: that sample's time stamp [ns].
        periods: the step in nominal periods (1.0 is a regular step).
    """

    sample: int
    stamp_ns: int
    periods: float


@dataclass(frozen=True)
class TimingReport:
    """Time stamps of one topic.

    Jitter is measured over the regular steps only (0 < step <= ``GAP_PERIODS`` periods); gaps,
    repeated and backward stamps are counted apart.

    Attributes:
        time_base: 'header' (JointState header stamps) or 'log' (bag receive times).
        rate_hz: mean rate, (count - 1) / time span [Hz]; None with fewer than two distinct stamps.
        nominal_period_s: the period steps are compared with [s]: the given period, the robot's
            IPO period, or the median step.
        median_period_s: median of the positive steps [s].
        jitter_std_ms: standard deviation of the regular steps [ms].
        jitter_p99_ms: 99th percentile of |step - nominal period| over the regular steps [ms].
        gap_count: number of gaps.
        gaps: the first ``MAX_LISTED`` gaps.
        repeated_count: steps of zero (a stamp repeats).
        repeated: sample indices of the first ``MAX_LISTED`` repeated stamps.
        backward_count: negative steps (a stamp goes backwards).
        backward: sample indices of the first ``MAX_LISTED`` backward stamps.
    """

    time_base: Literal['header', 'log']
    rate_hz: float | None
    nominal_period_s: float | None
    median_period_s: float | None
    jitter_std_ms: float | None
    jitter_p99_ms: float | None
    gap_count: int
    gaps: tuple[Gap, ...]
    repeated_count: int
    repeated: tuple[int, ...]
    backward_count: int
    backward: tuple[int, ...]


@dataclass(frozen=True)
class FieldStats:
    """One field (position, velocity or effort) of one joint, over the finite values.

    Attributes:
        minimum, maximum, mean: in the field's unit; None when no value is finite.
        non_finite: number of NaN or infinite values.
    """

    minimum: float | None
    maximum: float | None
    mean: float | None
    non_finite: int


@dataclass(frozen=True)
class JointReport:
    """Value ranges of one joint on one JointState topic.

    Attributes:
        name: joint name.
        position, velocity, effort: statistics, or None when the messages leave the field empty.
        position_outside_limits: fraction of samples outside the robot's position limits [-];
            None without a robot, a position field, or a joint of that name in the robot.
        velocity_outside_limits: fraction of samples with |velocity| above the robot's limit [-].
        effort_outside_limits: fraction of samples whose |effort| (a current on the motor
            currents, a joint torque on the joint states) lies beyond what train lets pass:
            ``TORQUE_FACTOR`` x what the torque limit needs (``plausibility.effort_bound``) [-].
        effort_peak_ratio: the largest |effort| over that bound [-] (above 1 train refuses).
        effort_kind: what the effort was checked as: 'current' [A] or 'torque' [N*m]; None
            when it was not.
        acceleration_beyond: on the joint states, the accelerations a controller sends along
            the motion beyond ``ACCELERATION_FACTOR`` x the joint's limit (the predictor's
            gate; train refuses the bag); None when none is, or not judged.
    """

    name: str
    position: FieldStats | None
    velocity: FieldStats | None
    effort: FieldStats | None
    position_outside_limits: float | None = None
    velocity_outside_limits: float | None = None
    effort_outside_limits: float | None = None
    effort_peak_ratio: float | None = None
    effort_kind: str | None = None
    acceleration_beyond: AccelerationExcess | None = None


@dataclass(frozen=True)
class TopicReport:
    """One topic of a bag.

    Attributes:
        name: topic name.
        msgtype: message type, e.g. 'sensor_msgs/msg/JointState'.
        count: messages read.
        timing: time stamp statistics.
        joints: per-joint statistics (JointState topics only; empty otherwise).
        undecodable: messages whose bytes do not deserialize (JointState topics).
        inconsistent: messages whose joint names or array lengths differ from the first message;
            they count in the timing but not in the joint statistics.
        first_inconsistent: sample index of the first such message, or None.
        contradictions: samples whose positions, velocities and the samples before them do not
            describe one motion (``dataset.consistency``; with a robot, finite samples only).
        first_contradiction: the first of them, described (sample, joint, mismatch), or None.
        velocity_scale: where no sample fails the gate, the joints whose velocities integrate
            to a multiple of their position change over the whole recording (a unit, a factor,
            a sign), described; or None.
        content: what the signal lacks (``dataset.content``: a constant or clipped label, a
            joint that does not move, a label against the URDF's gravity torque), one line
            each, the refusals marked.
        sampling: how the topic's sampling contradicts the robot's IPO period
            (``content.sampling_problem``), or None.
        invalid_stamps: messages whose header stamp is no time (``nanosec`` >= 1e9, a
            negative ``sec``: ``bag.header_stamp_problem``); train, the replay and the
            predictor refuse them. first_invalid_stamp: the first, described, or None.
        clock_step: where the log times step back while the header stamps advance (a clock
            step on the recorder, ``bag.clock_step``), the finding; the topic is then timed
            and numbered in header-stamp order, as train reads it. Else None.
    """

    name: str
    msgtype: str
    count: int
    timing: TimingReport
    joints: tuple[JointReport, ...] = ()
    undecodable: int = 0
    inconsistent: int = 0
    first_inconsistent: int | None = None
    contradictions: int = 0
    first_contradiction: str | None = None
    velocity_scale: str | None = None
    content: tuple[str, ...] = ()
    sampling: str | None = None
    invalid_stamps: int = 0
    first_invalid_stamp: str | None = None
    clock_step: str | None = None


@dataclass(frozen=True)
class ContractReport:
    """Whether the bag holds the contract's two topics with matching stamps and joints.

    Attributes:
        joint_states: the contract's joint state topic.
        motor_currents: the contract's motor current topic.
        missing: contract topics the bag lacks (or holds with another type than JointState).
        wrong_types: of those, the ones the bag holds with another type: (topic, type found).
        stamps_match: both topics carry the same header stamps, sample for sample, within
            ``plausibility.PAIRING_SHARE`` of the period; None when a topic is missing.
        first_mismatch: first sample index where the stamps do not pair (or the shorter topic
            ends).
        names_match: both topics name the same joints; None when a topic is missing or empty.
        joint_torques_only: no motor-current topic, and the joint states carry efforts (joint
            torque sensors): a recording for ``--target joint``, which needs no currents.
        empty_fields: (topic, field) the contract needs but the messages leave empty: position
            or velocity of the joint states, effort (the currents) of the motor currents.
        several_types: contract topics that hold messages of more than one type (the readers
            refuse them; the report covers their JointState messages).
    """

    joint_states: str
    motor_currents: str
    missing: tuple[str, ...]
    stamps_match: bool | None
    first_mismatch: int | None
    names_match: bool | None
    wrong_types: tuple[tuple[str, str], ...] = ()
    joint_torques_only: bool = False
    empty_fields: tuple[tuple[str, str], ...] = ()
    several_types: tuple[str, ...] = ()

    @property
    def is_met(self) -> bool:
        """Whether the bag meets the contract.

        Both topics are there, of one type each, with the fields it needs, and their stamps and
        joint names match.
        """
        return (
            not (self.missing or self.empty_fields or self.several_types)
            and bool(self.stamps_match)
            and bool(self.names_match)
        )


@dataclass(frozen=True, eq=False)
class BagReport:
    """What ``inspect_bag`` found.

    Attributes:
        path: the bag folder.
        storage: storage format ('mcap' or 'other').
        files: data file names.
        start_ns: first log time [ns since epoch]; start_iso: the same in ISO 8601, UTC.
        duration_s: log-time span [s].
        message_count: messages read on all topics.
        robot_name: the robot the bag was checked against, or None.
        topics: one report per topic.
        contract: the contract topics check.
        series: the stacked samples of each JointState topic (consistent messages only), kept
            for ``plot_report``.
        robot_joints: the joints of the robot checked against (empty without one): the
            contract topics must name exactly these, or limits cannot be checked.
        metadata_mismatches: where metadata.yaml's message counts, starting time or duration
            contradict the messages the files hold, one line each.
        several_types: topics holding messages of several types: (topic, ((type, messages
            read), ...)); the topic's report covers one of them (JointState where it is one).
    """

    path: Path
    storage: str
    files: tuple[str, ...]
    start_ns: int
    start_iso: str
    duration_s: float
    message_count: int
    robot_name: str | None
    topics: tuple[TopicReport, ...]
    contract: ContractReport
    series: Mapping[str, JointStateSeries] = field(default_factory=dict, repr=False)
    robot_joints: tuple[str, ...] = ()
    metadata_mismatches: tuple[str, ...] = ()
    several_types: tuple[tuple[str, tuple[tuple[str, int], ...]], ...] = ()

    def topic(self, name: str) -> TopicReport:
        """Return the report of one topic.

        Raises:
            BagError: the bag has no such topic (lists those it has).
        """
        for topic in self.topics:
            if topic.name == name:
                return topic
        raise BagError(
            f'{self.path}: no topic {name}; the bag has {[t.name for t in self.topics]}'
        )

    @property
    def problems(self) -> tuple[str, ...]:
        """One line per finding that ``load_recording`` would reject or a human should check."""
        lines = list(self.metadata_mismatches)
        for name, types in self.several_types:
            held = ', '.join(f'{t} ({n} message{"s" * (n != 1)})' for t, n in types)
            lines.append(
                f'{name}: holds {len(types)} message types: {held}; train and the other '
                f'readers refuse it (a topic carries one type); reported: its '
                f'{self.topic(name).msgtype} messages'
            )
        for topic in self.topics:
            lines += _topic_problems(topic)
        contract = self.contract
        for name, found in contract.wrong_types:
            lines.append(f'contract: {name} has type {found}, expected {JOINT_STATE}')
        if contract.missing and not contract.joint_torques_only:
            lines.append(f'contract: missing JointState topic(s) {list(contract.missing)}')
        elif contract.stamps_match is False:
            lines.append(
                f'contract: {contract.motor_currents} stamps differ from {contract.joint_states} '
                f'from sample {contract.first_mismatch} on'
            )
        for name, key in contract.empty_fields:
            what = ' (the motor currents)' if name == contract.motor_currents else ''
            lines.append(f'{name}: messages carry no {key}{what}')
        lines += self._joint_mismatches()
        if contract.names_match is False:
            lines.append(
                f'contract: {contract.motor_currents} and {contract.joint_states} name '
                f'different joints ({self._names_differ()})'
            )
        return tuple(lines)

    def _names_differ(self) -> str:
        """How the currents' joints differ from the joint states', in load_recording's words."""
        contract = self.contract
        states, currents = (
            [joint.name for joint in self.topic(name).joints]
            for name in (contract.joint_states, contract.motor_currents)
        )
        mismatch = joint_name_mismatch(currents, states)
        if mismatch is None:
            return 'the same joints, in another order: train matches them by name'
        return f'{contract.motor_currents} against {contract.joint_states}: {mismatch}'

    def _joint_mismatches(self) -> list[str]:
        """A contract topic whose joints are not the robot's: training would refuse the bag.

        Joints named twice (with the robot's joints otherwise) are ``_topic_problems``' line.
        """
        if not self.robot_joints:
            return []
        lines = []
        wanted = set(self.robot_joints)
        contract_topics = (self.contract.joint_states, self.contract.motor_currents)
        for topic in self.topics:
            names = [joint.name for joint in topic.joints]
            if topic.name not in contract_topics or not names or set(names) == wanted:
                continue
            unknown = [name for name in names if name not in wanted]
            lines.append(
                f'{topic.name}: joints do not match {self.robot_name} '
                f'({joint_name_mismatch(names, self.robot_joints)}); limits were not checked '
                f'for {unknown or "the missing joints"}'
            )
        return lines


def _topic_problems(topic: TopicReport) -> list[str]:
    lines: list[str] = []
    timing = topic.timing
    if topic.count == 0:
        lines.append(f'{topic.name}: no messages')
    if topic.sampling:
        lines.append(topic.sampling)
    if topic.clock_step:
        lines.append(topic.clock_step)
    if timing.gap_count:
        first = timing.gaps[0]
        lines.append(
            f'{topic.name}: {timing.gap_count} gap(s) > {GAP_PERIODS:g} periods, the first before '
            f'sample {first.sample} ({first.periods:.1f} periods)'
        )
    if timing.repeated_count:
        lines.append(
            f'{topic.name}: {timing.repeated_count} repeated stamp(s), the first at sample '
            f'{timing.repeated[0]}'
        )
    if timing.backward_count:
        lines.append(
            f'{topic.name}: {timing.backward_count} stamp(s) going backwards, the first at sample '
            f'{timing.backward[0]}'
        )
    if topic.undecodable:
        lines.append(f'{topic.name}: {topic.undecodable} message(s) do not deserialize')
    if topic.invalid_stamps:
        lines.append(
            f'{topic.name}: {topic.invalid_stamps} invalid header stamp(s), the first at '
            f'{topic.first_invalid_stamp} (train, the replay and the predictor refuse them)'
        )
    names = [joint.name for joint in topic.joints]
    if repeated := list(dict.fromkeys(name for name in names if names.count(name) > 1)):
        lines.append(
            f'{topic.name}: joint name(s) {repeated} repeated within a message (train refuses '
            'the bag)'
        )
    if topic.inconsistent:
        lines.append(
            f'{topic.name}: {topic.inconsistent} message(s) change joint names or array lengths, '
            f'the first at sample {topic.first_inconsistent}'
        )
    if topic.contradictions:
        lines.append(
            f'{topic.name}: {topic.contradictions} sample(s) do not follow from the ones before '
            f'them (train and replay refuse them), the first: {topic.first_contradiction}'
        )
    if topic.velocity_scale:
        lines.append(
            f'{topic.name}: the velocities contradict the positions over the whole recording '
            f'by a factor (train and replay refuse it): {topic.velocity_scale}'
        )
    for joint in topic.joints:
        for key in FIELDS:
            stats: FieldStats | None = getattr(joint, key)
            if stats is not None and stats.non_finite:
                lines.append(
                    f'{topic.name}: {joint.name} {key}: {stats.non_finite} non-finite value(s)'
                )
        for key, fraction in (
            ('position', joint.position_outside_limits),
            ('velocity', joint.velocity_outside_limits),
        ):
            if fraction:
                lines.append(
                    f'{topic.name}: {joint.name} {key} outside the robot limits in '
                    f'{100 * fraction:.2f} % of samples'
                )
        if joint.effort_outside_limits:
            lines.append(_effort_problem(topic.name, joint))
        if joint.acceleration_beyond is not None:
            lines.append(joint.acceleration_beyond.describe(topic.name, joint.name))
    lines += [f'{topic.name}: {line}' for line in topic.content]
    return lines


def _effort_problem(topic: str, joint: JointReport) -> str:
    """The line of a joint whose efforts exceed what the robot's torque limits need."""
    fraction = joint.effort_outside_limits or 0.0
    peak = joint.effort_peak_ratio or 0.0
    line = (
        f'{topic}: {joint.name} effort beyond {TORQUE_FACTOR:g} x what the torque limit needs in '
        f'{100 * fraction:.2f} % of samples, up to {peak:.3g} x that bound (train refuses the bag)'
    )
    if peak >= SCALE_PEAK_FACTOR:
        line += '; far beyond any limit question: ' + (
            "check the currents' unit (A, not mA) and the drives' gear_ratio and torque_constant"
            if joint.effort_kind == 'current'
            else 'check the unit and scale of the torques (N*m)'
        )
    return line
