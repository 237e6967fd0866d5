"""Diagnose a recording: where the nominal model and the measurements disagree, and why.

1. Nominal model: URDF RNEA plus the datasheet rotor inertia, on a controller's inputs (the
   recorded motion, ``dataset.inputs``); residual r = filtered label minus the nominal torque
   filtered exactly like the label.
2. Candidates: every named effect on every joint (``candidates``), its columns filtered exactly
   like the label, edges trimmed where the zero-phase filter starts up. With the study's
   preprocessing (``PreprocessConfig.mode='study'``) the columns are built on the filtered
   motion and meet the filtered label unfiltered, as the study's instantaneous models do.
3. Noise: the filtered label's noise level and correlation time from the raw label's
   high-frequency floor and the filter (``statistics``); rows are weighted by them.
4. Selection: forward group selection with F test, BIC, held-out gain and plausibility; alias sets;
   untestable effects; the unexplained remainder (``selection``).
5. Refit with the selected effects, held-out RMSE before/after each (waterfall), variance
   explained, parameters with confidence intervals for the effective sample size.

The problem lives in ``problem``, the candidates and their tuning in ``candidate_set``, the
result types in ``result``; this module runs the steps and assembles the result.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy import stats

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.recording import Recording
from id_learning.dataset.statistics import (
    integrated_autocorrelation,
)
from id_learning.diagnosis.aliases import AliasSet, find_aliases, given_way
from id_learning.diagnosis.candidate_set import CandidateSet
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.design import PARTS, Design, Fit
from id_learning.diagnosis.heldout import (
    BlockTest,
    fallback_joints,
    judge_effects,
    test_blocks,
)
from id_learning.diagnosis.intervals import ALIAS_ALTERNATIVES, IntervalRule
from id_learning.diagnosis.locate import locate_residual
from id_learning.diagnosis.parameters import describe_parameters
from id_learning.diagnosis.problem import (
    ResidualProblem,
    as_datasets,
    as_label,
    column_motion,
    evaluation_rows,
)
from id_learning.diagnosis.result import DiagnosisResult, FoundEffect, Remainder
from id_learning.diagnosis.selection import (
    BUDGET_STOP,
    GroupEvaluation,
    SelectionResult,
    forward_select,
    noise_consistency,
    refused_records,
    rejected_record,
    selection_record,
)
from id_learning.diagnosis.separation import separating_motion
from id_learning.errors import DatasetError
from id_learning.physics.effects import effect
from id_learning.physics.terms import EffectSpec
from id_learning.robot.config import RobotConfig
from id_learning.threads import single_blas_thread

_LOG = logging.getLogger(__name__)
#: The share of a time budget in which the diagnosis's optional steps may start.
_STEPS_SHARE = 0.6
#: Times the selection resumes after its effects' settings are refined.
_RESUMPTIONS = 2


__all__ = [
    'DiagnosisResult',
    'FoundEffect',
    'Remainder',
    'augmented_torque',
    'column_motion',
    'evaluation_rows',
    'filtered_prediction',
    'run_diagnosis',
]


# -- the diagnosis --------------------------------------------------------------------------------
@single_blas_thread
def run_diagnosis(
    data: Recording | Dataset | Sequence[Recording | Dataset],
    robot: RobotConfig,
    config: DiagnosisConfig | None = None,
) -> DiagnosisResult:
    """The diagnosis without writing anything (see ``diagnose``)."""
    config = config or DiagnosisConfig()
    budget = _Budget(config.max_seconds)
    problem = ResidualProblem(as_datasets(data, robot, config), robot, config)
    candidates = CandidateSet(problem)
    y = {part: problem.residual(part) for part in PARTS}
    n_eff = {part: problem.n_effective(part) for part in PARTS}

    def select(start: Sequence[str] = ()) -> SelectionResult:
        return forward_select(
            candidates.design(y, n_eff),
            candidates.testable,
            candidates.plausible,
            significance=config.significance,
            max_groups=config.max_effects,
            conflicts=candidates.conflicts,
            noise_significance=config.noise_significance,
            noise_tolerance=config.noise_tolerance,
            last_resort=candidates.is_general,
            start=start,
            deadline=budget.deadline,
            joint_of=lambda label: candidates.specs[label].joint,
        )

    def settled(groups: list[str]) -> list[str]:
        """Refine a selection, give the whole-model columns its effects; the new labels."""
        refined = candidates.refine(groups, y, n_eff)
        candidates.whole_model(refined, y, n_eff)
        # The friction's load from this selection's fit, not the one before whole_model.
        return candidates.load_on_model(refined, y, n_eff)

    selection = select()
    selected = candidates.refine(selection.selected, y, n_eff)
    # Asked first: the whole model's forms relabel the delay and torque-constant candidates,
    # which only a new selection can then take up.
    if budget.allows('the selection with the whole model') and candidates.whole_model(
        selected, y, n_eff
    ):
        # Delay and torque-constant candidates now see the whole model: select again, then
        # give their columns the final effects.
        selection = select()
        selected = settled(selection.selected)
    for _ in range(_RESUMPTIONS):
        if not budget.allows('the selection resumed after refinement'):
            break
        # A refined setting can make a candidate plausible that was not: with the payload's
        # own inertia found, the flange link's parameters no longer need it (twin seed 21 at
        # 600 s, every effect on: they were refused for 0.19 kg*m^2 on body 6 and left a
        # remainder of 11 times the noise). The selection resumes from the refined effects.
        resumed = select(start=selected)
        if len(resumed.selected) == len(selected):
            break
        selection = replace(resumed, steps=[*selection.steps, *resumed.steps])
        selected = settled(resumed.selected)
    design = candidates.design(y, n_eff)

    def aliases_of(groups: list[str]) -> list[AliasSet]:
        return find_aliases(
            design,
            groups,
            candidates.testable,
            candidates.plausible,
            significance=config.alias_significance,
            variants=candidates.variants,
            swappable=candidates.swappable,
        )

    aliases = aliases_of(selected)
    specific = (
        candidates.special_cases(selected, aliases)
        if budget.allows('the special cases of the alias sets')
        else selected
    )
    if specific != selected:
        before, selected = selected, candidates.refine(specific, y, n_eff)
        design = candidates.design(y, n_eff)
        given = _springs_given_way(candidates, before, specific, selected)
        aliases = given_way(aliases, given, aliases_of(selected))
    aliases = candidates.without_generalisations(aliases)
    blocks = test_blocks(problem, design.residual(design.fit(selected), 'test'))
    steps = list(selection.steps)
    unconfirmed = _unconfirmed_springs(candidates, design, selected, blocks, config)
    if unconfirmed:
        # An unconfirmed spring gives way to the alias that leaves least of it, else goes ...
        stand_in = {label: _best_other(label, aliases, candidates) for label in unconfirmed}
        kept = [label not in unconfirmed or stand_in[label] for label in selected]
        saved = candidates.saved()
        dropped = candidates.refine(
            [stand_in.get(label) or label for label, k in zip(selected, kept, strict=True) if k],
            y,
            n_eff,
        )
        without = candidates.design(y, n_eff)
        # ... unless the model it leaves, refitted (the load columns then lose the spring's
        # torque too), leaves a structured remainder where there was none on a spring's joint.
        joints = {candidates.specs[g].joint_name for g in unconfirmed}
        if _newly_structured(problem, (design, selected), (without, dropped)) & joints:
            candidates.restore(saved)
        else:
            steps = [st for st, keep in zip(steps, kept, strict=True) if keep]
            selected, design = dropped, without
            now = candidates.without_generalisations(aliases_of(selected))
            aliases = given_way(aliases, stand_in, now)
    return _assemble(
        problem,
        candidates,
        design,
        selection=selection,
        steps=steps,
        selected=selected,
        aliases=aliases,
        blocks=blocks,
        cut_short=budget.cut_short(selection),
    )


class _Budget:
    """The diagnosis's time budget: whether a step may start, and what was cut short.

    Steps start only within ``_STEPS_SHARE`` of the budget: the rest is left for what always
    runs (the springs' held-out check, the final refit, the intervals and alias sets).
    """

    def __init__(self, seconds: float | None) -> None:
        self.deadline = None if seconds is None else time.perf_counter() + _STEPS_SHARE * seconds
        self.skipped: list[str] = []

    def allows(self, step: str) -> bool:
        """Whether the budget leaves time for ``step``; noted as cut short when not."""
        if self.deadline is None or time.perf_counter() <= self.deadline:
            return True
        self.skipped.append(step)
        return False

    def cut_short(self, selection: SelectionResult) -> list[str]:
        """The steps left out, the selection's own steps first."""
        stopped = ['selection steps'] if selection.stop_reason == BUDGET_STOP else []
        return [*stopped, *self.skipped]


def _separated(
    problem: ResidualProblem, design: Design, final: Fit, aliases: list[AliasSet]
) -> list[AliasSet]:
    """The alias sets with their closest alternatives, and the motion that tells each apart."""
    out = []
    for alias in aliases:
        short = alias.closest(ALIAS_ALTERNATIVES)
        separation = {
            member: separating_motion(problem, design, final, short.representative, member)
            for member in short.alternatives()
        }
        out.append(replace(short, separation=separation))
    return out


def _newly_structured(
    problem: ResidualProblem, before: tuple[Design, list[str]], after: tuple[Design, list[str]]
) -> set[str]:
    """Joints whose remainder is structured after a change of the model and was not before."""
    flags = [
        {r.joint for r in _remainder(problem, design, design.fit(groups), problem.config)
         if r.structured}
        for design, groups in (before, after)
    ]  # fmt: skip
    return flags[1] - flags[0]


def _springs_given_way(
    candidates: CandidateSet, before: list[str], specific: list[str], after: list[str]
) -> dict[str, str | None]:
    """Each spring that ``special_cases`` replaced -> what took its place (refined)."""
    return {
        old: new for old, new in zip(before, after, strict=True)
        if old not in specific and effect(candidates.specs[old].name).claims_hardware
    }  # fmt: skip


def _best_other(label: str, aliases: list[AliasSet], candidates: CandidateSet) -> str | None:
    """The member of ``label``'s alias set, no spring, that leaves least of it; None if none."""
    for alias in aliases:
        if alias.representative == label:
            others = [
                m
                for m in alias.members[1:]
                if not effect(candidates.specs[m].name).claims_hardware
            ]
            if others:
                return min(others, key=lambda m: alias.unexplained.get(m, np.inf))
    return None


def _unconfirmed_springs(
    candidates: CandidateSet,
    design: Design,
    selected: list[str],
    blocks: tuple[np.ndarray, float],
    config: DiagnosisConfig,
) -> list[str]:
    """Gravity springs whose held-out gain is not significant over blocks of time.

    A spring claims hardware the robot may not have, and on real robots it stands in for other
    position-dependent errors (offsets, link parameters) on the training part; it is named only
    when the held-out part confirms it with every other effect in the model.
    """
    springs = [label for label in selected if effect(candidates.specs[label].name).claims_hardware]
    if not springs:
        return []
    tests = judge_effects(design, selected, design.fit(selected), *blocks)
    return [
        label
        for label in springs
        if not (tests[label].judged and tests[label].p_value < config.significance)
    ]


def augmented_torque(
    result: DiagnosisResult,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    jerk: np.ndarray | None = None,
) -> np.ndarray:
    """Torque of the refit model (nominal plus every effect, aliases included).

    The nominal torque alone on its fallback joints (``DiagnosisResult.nominal_joints``).

    Args:
        result: a diagnosis.
        q: (N, n) joint positions [rad].
        v: (N, n) joint velocities [rad/s].
        a: (N, n) joint accelerations [rad/s^2].
        jerk: (N, n) joint jerks [rad/s^3] for the signal-delay term; zero if None (the state
            the delay holds back then lacks the jerk's share).

    Returns:
        (N, n) tau_u (or joint torque, per ``result.target``) [N*m].
    """
    return result.augmented_model.torque(q, v, a, jerk)


def filtered_prediction(
    result: DiagnosisResult, recording: Recording, *, with_effects: bool = True
) -> tuple[Dataset, np.ndarray]:
    """The refit (or nominal) model's torque along a recording, as the diagnosis meets the label.

    The model sees the recording's motion the way the diagnosis fitted it (``column_motion``),
    and its torque passes the label's zero-phase filter (the study's preprocessing: as is), so
    it compares sample by sample with the dataset's label ``tau`` (or with a noise-free torque
    filtered the same way).

    Returns:
        (the preprocessed dataset, (N, n) model torque filtered like the label [N*m]).
    """
    config = result.settings or DiagnosisConfig()
    if len(recording.segment_starts) > 1:
        raise DatasetError(
            f'{recording.source}: holds {len(recording.segment_starts)} segments; compare each '
            '(Recording.segments()) on its own'
        )
    (dataset,) = as_datasets(recording, result.robot, config)
    q, v, a, jerk = column_motion(dataset)
    if with_effects:
        tau = augmented_torque(result, q, v, a, jerk)
    else:
        tau = result.nominal_model.evaluate(q, v, a).tau_nominal
    return dataset, as_label(tau, dataset)


def _waterfall(
    design: Design, selected: Sequence[str], weights: np.ndarray
) -> tuple[list[tuple[str, np.ndarray]], dict[str, np.ndarray], dict[str, float]]:
    """Held-out RMSE after each added effect, and the held-out variance each one removed.

    The share is of the nominal residual's held-out variance, per joint and over all joints
    weighted by the noise.
    """
    previous = design.y['test']  # the nominal model's (a fit holds a linearisation's constant)
    base = np.mean(previous**2, axis=0)
    base_total = float(np.sum(weights * np.sum(previous**2, axis=0)))
    waterfall, explained, explained_total = [], {}, {}
    for k, label in enumerate(selected, start=1):
        residual = design.residual(design.fit(selected[:k]), 'test')
        waterfall.append((label, _rmse(residual)))
        gain = np.mean(previous**2, axis=0) - np.mean(residual**2, axis=0)
        explained[label] = np.where(base > 0, gain / np.where(base > 0, base, 1.0), 0.0)
        total = float(
            np.sum(weights * (np.sum(previous**2, axis=0) - np.sum(residual**2, axis=0)))
        )
        explained_total[label] = total / base_total if base_total > 0 else 0.0
        previous = residual
    return waterfall, explained, explained_total


def _assemble(
    problem: ResidualProblem,
    candidates: CandidateSet,
    design: Design,
    *,
    selection: SelectionResult,
    steps: list[GroupEvaluation],
    selected: list[str],
    aliases: list[AliasSet],
    blocks: tuple[np.ndarray, float],
    cut_short: list[str],
) -> DiagnosisResult:
    """Refit with the selected effects and collect what the report shows.

    An effect is named with high confidence only when its held-out gain over blocks of time is
    significant (``heldout.judge_effects``) and no structured remainder on its joints outweighs
    it; joints the effects do not improve on the held-out part fall back to the nominal model.
    """
    robot, config = problem.robot, problem.config
    final = design.fit(selected)
    tests = judge_effects(design, selected, final, *blocks)
    fallback = fallback_joints(design, final, blocks[0])
    waterfall, explained, explained_total = _waterfall(design, selected, problem.weights)
    remainder = _remainder(problem, design, final, config)
    members = {label for alias in aliases for label in alias.members}
    t_crit = float(stats.t.ppf(0.975, max(design.n_eff_train - final.rank, 1.0)))
    effects = []
    intervals = IntervalRule(problem, candidates, design, final, remainder, aliases=aliases)
    for step, label in zip(steps, selected, strict=True):
        spec = candidates.specs[label]
        theta = design.physical(final, label)
        inflation = intervals.inflation(label, spec)
        half = t_crit * np.sqrt(
            np.clip(np.diag(inflation * design.physical_covariance(final, label)), 0, None)
        )
        value, covariance = intervals.parameters(label, inflation)
        interval_covariance = t_crit**2 * covariance
        value_half = np.sqrt(np.clip(np.diag(interval_covariance), 0, None))
        rms = _rmse(np.concatenate([design.contribution(final, label, p) for p in PARTS]))
        test = tests[label]
        effects.append(
            FoundEffect(
                spec=spec,
                status='alias' if label in members else 'found',
                confidence=_confidence(
                    spec,
                    rms,
                    test,
                    remainder,
                    fallback=fallback,
                    closed=selection.refused,
                    config=config,
                ),
                coefficients=theta,
                coefficients_ci=np.stack([theta - half, theta + half], axis=1),
                parameters=describe_parameters(
                    spec,
                    value,
                    value_half,
                    problem.model,
                    interval_covariance,
                    settings=intervals.settings(label, inflation, t_crit),
                ),
                contribution_rms_nm=rms,
                variance_explained=explained[label],
                variance_explained_total=explained_total[label],
                selection=selection_record(step, test) | {'interval_inflation': inflation},
            )
        )
    after_test = _after(design, final, 'test', fallback)
    times = {part: problem.times(part) for part in PARTS}
    location = locate_residual(
        design.y['train'],
        problem.part('q', 'train'),
        problem.part('v', 'train'),
        problem.part('a', 'train'),
        load=problem.joined_quantities().tau_rigid,
        t=times['train'],
        joints=robot.joints,
    )
    series = {
        'time_s': np.concatenate([times[part] for part in PARTS]),
        'is_test': np.concatenate([np.full(len(times[part]), part == 'test') for part in PARTS]),
        'label': np.concatenate([problem.label(part) for part in PARTS]),
        'residual_before': np.concatenate([design.y[part] for part in PARTS]),
        'residual_after': np.concatenate(
            [_after(design, final, part, fallback) for part in PARTS]
        ),
    }
    return DiagnosisResult(
        robot=robot,
        target=problem.datasets[0].target,
        sources=[d.source for d in problem.datasets],
        duration_s=float(sum(len(d.q) for d in problem.datasets) * problem.period),
        noise=problem.noise,
        effective_samples=design.n_effective,
        effects=effects,
        alias_sets=_separated(problem, design, final, aliases),
        untestable=candidates.untestable_summary(),
        remainder=remainder,
        rmse_before_nm=_rmse(design.y['test']),
        rmse_after_nm=_rmse(after_test),
        nominal_joints=[robot.joints[j] for j in fallback],
        waterfall=waterfall,
        location=location,
        stop_reason=selection.stop_reason,
        cut_short=cut_short,
        rejected=rejected_record(selection),
        refused=refused_records(design, final, selection.refused, robot.joints),
        marginalised=intervals.unknowns,
        stand_ins=intervals.stand_ins,
        config=config.to_dict()
        | {'n_candidates': len(candidates.testable), 'level': selection.level},
        series=series,
        settings=config,
    )


def _confidence(
    spec: EffectSpec,
    rms: np.ndarray,
    test: BlockTest,
    remainder: list[Remainder],
    *,
    fallback: list[int],
    closed: Mapping[int, GroupEvaluation],
    config: DiagnosisConfig,
) -> str:
    """'high' or 'low' confidence in an effect.

    High only for a significant held-out gain over blocks of time, on a joint that keeps the
    effect and no refused candidate closed, after which no structured remainder outweighs it
    and, for a joint effect, its joint's remainder is near the noise.
    """
    joints = [r.joint for r in remainder]
    outweighed = any(r.structured and 0 < rms[joints.index(r.joint)] < r.rms_nm for r in remainder)
    structured = {r.joint for r in remainder if r.structured}
    low = (
        outweighed
        or not (test.judged and test.p_value < config.significance)
        or (spec.joint is not None and spec.joint in fallback)
        or spec.joint_name in structured
        or spec.joint in closed
    )
    return 'low' if low else 'high'


def _after(design: Design, final: Fit, part: str, fallback: list[int]) -> np.ndarray:
    """The saved model's residual on a part: the nominal one on the fallback joints."""
    residual = design.residual(final, part)
    residual[:, fallback] = design.y[part][:, fallback]
    return residual


def _rmse(x: np.ndarray) -> np.ndarray:
    out: np.ndarray = np.sqrt(np.mean(np.square(x), axis=0))
    return out


def _remainder(
    problem: ResidualProblem, design: Design, fit: Fit, config: DiagnosisConfig
) -> list[Remainder]:
    _, ratio, p_values = noise_consistency(
        design, fit, config.noise_significance, config.noise_tolerance
    )
    residual = np.concatenate([design.residual(fit, part) for part in ('train', 'test')])
    rms = _rmse(residual)
    train = design.residual(fit, 'train')
    out = []
    for j, joint in enumerate(problem.robot.joints):
        tau_acf = integrated_autocorrelation(train[:, j]) * problem.step
        correlation = tau_acf / problem.noise.correlation_samples[j]
        # Larger than the noise (variance test and size), or above it and correlated far
        # beyond the filter's correlation time (structure, where filtered noise is white).
        larger = p_values[j] <= config.noise_significance and ratio[j] > config.noise_tolerance
        correlated = correlation > config.structure_correlation_ratio and ratio[j] > 1.1
        structured = bool(larger or correlated)
        out.append(
            Remainder(
                joint=joint,
                rms_nm=float(rms[j]),
                noise_nm=float(problem.noise.filtered_std_nm[j]),
                ratio=float(ratio[j]),
                p_value=float(p_values[j]),
                correlation_ratio=float(correlation),
                structured=structured,
            )
        )
    return out
