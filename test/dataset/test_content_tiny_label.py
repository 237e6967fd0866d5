"""A label far too small for a moving joint (a gear ratio written upside down) is named.

Probe 15 (A49): joint_1's gear ratio given as 1/205 (joint turns per motor turn) made its label
42025 x too small; on the vertical axis no gravity torque judges the scale, and inspect and train
said nothing. Friction alone takes percents of a joint's torque limit to move it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from id_learning.dataset.content import TINY_LABEL_SHARE, gravity_findings, tiny_label_findings
from id_learning.robot import load_robot_config
from id_learning.robot.drives import torque_per_ampere

REPO = Path(__file__).resolve().parents[2]
ROBOT = load_robot_config(REPO / 'config/mabi_max100.yaml')
N = 2000


def motion() -> tuple[np.ndarray, np.ndarray]:
    """Positions [rad] moving every joint, and a friction-like joint torque [N*m]."""
    t = 0.008 * np.arange(N)
    q = 0.5 * np.sin(np.outer(t, 0.3 + 0.1 * np.arange(ROBOT.n_joints)))
    v = np.gradient(q, 0.008, axis=0)
    tau = 0.03 * ROBOT.limits.torque * np.tanh(50 * v) + 0.01 * ROBOT.limits.torque * v
    return q, tau


def test_a_sound_label_gives_no_finding() -> None:
    q, tau = motion()
    assert tiny_label_findings(q, tau, ROBOT, quantity='motor current') == []


@pytest.mark.parametrize('factor', [1 / 205**2, 1e-3])
def test_a_label_scaled_far_down_on_one_joint_is_named_with_its_share(factor: float) -> None:
    q, tau = motion()
    tau[:, 0] *= factor
    findings = tiny_label_findings(q, tau, ROBOT, quantity='motor current')
    assert [finding.joint for finding in findings] == [ROBOT.joints[0]]
    assert findings[0].kind == 'nominal_scale'
    assert not findings[0].refuses
    assert 'gear_ratio (motor turns per joint turn)' in findings[0].text


def test_the_threshold_is_the_share_of_the_torque_limit() -> None:
    q, tau = motion()
    p99 = np.percentile(np.abs(tau[:, 0]), 99)
    just_above = tau.copy()
    just_above[:, 0] *= 1.01 * TINY_LABEL_SHARE * ROBOT.limits.torque[0] / p99
    assert tiny_label_findings(q, just_above, ROBOT, quantity='joint torque') == []
    just_below = tau.copy()
    just_below[:, 0] *= 0.99 * TINY_LABEL_SHARE * ROBOT.limits.torque[0] / p99
    assert len(tiny_label_findings(q, just_below, ROBOT, quantity='joint torque')) == 1


def test_a_still_joint_with_no_torque_is_no_finding() -> None:
    q, tau = motion()
    q[:, 0] = 0.1
    tau[:, 0] = 1e-6
    assert tiny_label_findings(q, tau, ROBOT, quantity='motor current') == []


def test_gravity_findings_name_it_from_currents_through_the_drive_train() -> None:
    q, tau = motion()
    current = tau / torque_per_ampere(ROBOT.drives)
    current[:, 0] /= 205.0**2

    def no_gravity(position: np.ndarray) -> np.ndarray:
        return np.zeros_like(position)

    findings = gravity_findings(q, current, ROBOT, no_gravity)
    assert [finding.joint for finding in findings] == [ROBOT.joints[0]]
