"""An interval holds what the data leave open between an alias set's members."""

from __future__ import annotations

import numpy as np
from support import twin_config

from id_learning.diagnosis import DiagnosisConfig
from id_learning.diagnosis.aliases import AliasSet
from id_learning.diagnosis.candidate_set import CandidateSet
from id_learning.diagnosis.intervals import IntervalRule
from id_learning.diagnosis.pipeline import _remainder
from id_learning.diagnosis.problem import ResidualProblem, as_datasets
from id_learning.twin import simulate

FRICTION = {
    'coulomb_friction': {'enabled': True, 'level': [120.0, 160.0, 90.0, 20.0, 15.0, 6.0]},
    'viscous_friction': {'enabled': True, 'coefficient': [300.0, 400.0, 220.0, 45.0, 35.0, 15.0]},
}


def test_a_value_an_alias_alternative_moves_gets_that_move_in_its_interval():
    config = twin_config(120.0, FRICTION, seed=5)
    twin = simulate(config)
    settings = DiagnosisConfig()
    problem = ResidualProblem(
        as_datasets(twin.recording, config.robot, settings), config.robot, settings
    )
    candidates = CandidateSet(problem)
    y = {part: problem.residual(part) for part in ('train', 'test')}
    n_eff = {part: problem.n_effective(part) for part in ('train', 'test')}
    design = candidates.design(y, n_eff)
    specs = candidates.specs

    def on_joint_3(name: str) -> str:
        (label,) = [
            g for g in candidates.testable if specs[g].name == name and specs[g].joint == 2
        ]
        return label

    selected = [g for g in candidates.testable if specs[g].name in FRICTION]
    kept, viscous = on_joint_3('coulomb_friction'), on_joint_3('viscous_friction')
    other = on_joint_3('load_dependent_friction')
    final = design.fit(selected)
    remainder = _remainder(problem, design, final, settings)
    alias = AliasSet(kept, [kept, other], unexplained={other: 0.0})

    plain = IntervalRule(problem, candidates, design, final, remainder)
    wide = IntervalRule(problem, candidates, design, final, remainder, aliases=[alias])
    value, covariance = plain.parameters(viscous, 1.0)
    same, widened = wide.parameters(viscous, 1.0)

    np.testing.assert_allclose(same, value)
    # The move: the viscous coefficient refitted with load-dependent friction in Coulomb's place.
    groups = [other if g == kept else g for g in selected]
    unknowns, priors = candidates.datasheet_unknowns(groups)
    swapped = wide.base.with_priors(priors).fit([*groups, *unknowns])
    move = wide.marginal_design.physical(swapped, viscous) - value
    assert abs(move[0]) > 0.1 * np.sqrt(covariance[0, 0])  # the swap matters here
    np.testing.assert_allclose(widened - covariance, np.outer(move, move), rtol=1e-9)
