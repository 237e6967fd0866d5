"""A balancer's geometry is refined within physical arm ratios."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from support import twin_config

from id_learning.diagnosis import DiagnosisConfig
from id_learning.diagnosis.candidate_set import CandidateSet
from id_learning.diagnosis.problem import ResidualProblem, as_datasets
from id_learning.physics.balancer import BALANCER_RATIOS
from id_learning.robot.drives import current_from_motor_torque
from id_learning.twin import simulate

FRICTION = {
    'coulomb_friction': {'enabled': True, 'level': [120.0, 160.0, 90.0, 20.0, 15.0, 6.0]},
    'viscous_friction': {'enabled': True, 'coefficient': [300.0, 400.0, 220.0, 45.0, 35.0, 15.0]},
}


def test_the_arm_ratio_stays_in_the_grid_when_the_data_pull_it_to_zero():
    """sin q and sin 2q are what the balancer's three columns tend to as the ratio goes to 0 (an
    ill-posed pair); a torque of that shape pulls the ratio down, and it stops at the grid's
    smallest."""
    config = twin_config(120.0, FRICTION, seed=12)
    twin = simulate(config)
    q = twin.q_true[:, 1]
    extra = np.zeros_like(twin.q_true)
    extra[:, 1] = -1500.0 * np.sin(q) - 600.0 * np.sin(2.0 * q)
    recording = replace(
        twin.recording,
        current=twin.recording.current + current_from_motor_torque(extra, config.robot.drives),
    )
    diagnosis = DiagnosisConfig(gravity_spring_joints=('joint_2',))
    problem = ResidualProblem(
        as_datasets(recording, config.robot, diagnosis), config.robot, diagnosis
    )
    candidates = CandidateSet(problem)
    y = {part: problem.residual(part) for part in ('train', 'test')}
    n_eff = {part: problem.n_effective(part) for part in ('train', 'test')}
    friction = [label for label in candidates.testable if candidates.specs[label].name in FRICTION]
    (spring,) = [
        label for label in candidates.testable if candidates.specs[label].name == 'gravity_spring'
    ]
    refined = candidates.refine([*friction, spring], y, n_eff)
    settings = candidates.specs[refined[-1]].settings
    assert settings['ratio'] == min(BALANCER_RATIOS)
    assert abs(settings['phase_rad']) < 0.05
