"""Inspect's judgement of the label against the motion and the URDF's gravity torque.

Kept apart from ``inspect`` so that the bag reading stays one module: this part only pairs the
decoded series and adds ``content.sign_findings`` and ``content.gravity_findings`` lines to
the label topic's report.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from id_learning.bag import JointStateSeries
from id_learning.dataset.content import (
    GravityTorque,
    gravity_findings,
    gravity_in_label_unit,
    sign_findings,
)
from id_learning.dataset.inspect_report import TopicReport
from id_learning.dataset.plausibility import first_unpaired
from id_learning.robot.config import RobotConfig, TopicConfig

__all__ = ['with_nominal_lines']


def _nominal(
    series: Mapping[str, JointStateSeries],
    topics: TopicConfig,
    robot: RobotConfig | None,
    gravity: GravityTorque | None,
) -> tuple[str, tuple[tuple[str, str], ...]]:
    """(label topic, (joint, ``content.gravity_findings`` line)) where the contract has a label.

    Judged only where the positions and the label name the robot's joints and pair sample for
    sample (the contract's own check reports it otherwise).
    """
    states = series.get(topics.joint_states)
    label_topic = topics.motor_currents if topics.motor_currents in series else topics.joint_states
    label = series.get(label_topic)
    if robot is None or gravity is None or states is None or label is None:
        return label_topic, ()
    if states.position is None:
        return label_topic, ()
    if (
        label.effort is None
        or len(label.effort) != len(states.position)
        or len(states.position) < 3
    ):
        return label_topic, ()
    if not all(sorted(s.names) == sorted(robot.joints) for s in (states, label)):
        return label_topic, ()
    if first_unpaired(states.stamps_ns, label.stamps_ns, robot.ipo_period_s) is not None:
        return label_topic, ()
    q = states.position[:, [states.names.index(name) for name in robot.joints]]
    effort = label.effort[:, [label.names.index(name) for name in robot.joints]]
    quantity, unit = (
        ('motor current', 'A') if label_topic == topics.motor_currents else ('joint torque', 'N*m')
    )
    held = gravity_in_label_unit(q, robot, gravity, quantity)
    findings = sign_findings(q, effort, robot.joints, quantity=quantity, unit=unit, held=held)
    findings += gravity_findings(q, effort, robot, gravity, quantity=quantity)
    return label_topic, tuple((finding.joint, finding.text) for finding in findings)


def with_nominal_lines(
    reports: Sequence[TopicReport],
    series: Mapping[str, JointStateSeries],
    topics: TopicConfig,
    robot: RobotConfig | None,
    gravity: GravityTorque | None,
) -> list[TopicReport]:
    """The reports, the label topic's with its gravity findings added to its content lines.

    A label the content check refuses is not judged, nor the joints beyond the drives' limits
    (each has its own line already).
    """
    label_topic, lines = _nominal(series, topics, robot, gravity)
    out = list(reports)
    for k, report in enumerate(out):
        if report.name != label_topic:
            continue
        if any(line.endswith('refuse the bag') for line in report.content):
            break
        beyond = {joint.name for joint in report.joints if joint.effort_outside_limits}
        kept = tuple(text for joint, text in lines if joint not in beyond)
        out[k] = replace(report, content=report.content + kept)
    return out
