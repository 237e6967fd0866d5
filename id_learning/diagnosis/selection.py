"""Forward group selection with statistical stopping, and the design every fit runs on.

Every candidate is a group of filtered regressor columns. Rows are joint-samples; each joint's
rows are weighted by d / (sigma_j^2 tau_j) (noise variance sigma_j^2 of the filtered label,
correlation time tau_j samples, every d-th sample kept), so a residual sum of squares is in units
of independent noise samples and the effective sample size is sum_j N_j d / tau_j. A candidate
enters when, given the effects already in,

1. its gain is significant: F test with the effective sample size, at the family-wise level split
   among the candidates of the step (Bonferroni);
2. the information criterion improves: n_eff ln(RSS' / RSS) + k ln(n_eff) < 0 (BIC);
3. the held-out (contiguous, later) part improves;
4. every fitted value is physically plausible.

Selection stops when no candidate passes, or when the residual is consistent with the noise level
and no candidate is overwhelmingly significant. Alias sets: ``aliases``.

A candidate that passes the first three tests but whose own fitted value is implausible, and that
explains a joint's residual far better than any plausible candidate there (``REFUSAL_DOMINANCE``),
is recorded as refused and closes that joint: what it explains is a form the library does not
hold, and the weaker candidates would only fill it with wrong names.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from id_learning.dataset.statistics import f_test
from id_learning.diagnosis.design import PARTS, Design, Fit
from id_learning.diagnosis.heldout import BlockTest

__all__ = [
    'BUDGET_STOP',
    'GroupEvaluation',
    'SelectionResult',
    'forward_select',
    'refused_records',
    'rejected_record',
    'selection_record',
]

_LOG = logging.getLogger(__name__)

#: The stop reason of a selection cut short by its time budget.
BUDGET_STOP = 'the time budget ran out'
#: A refused candidate closes its joint when its held-out gain is this many times the best
#: plausible candidate's on that joint (each would then explain at most half of it).
REFUSAL_DOMINANCE = 2.0
#: ... and when it leaves the joint's residual within this multiple of the noise tolerance.
NEAR_NOISE = 1.5


@dataclass(frozen=True)
class GroupEvaluation:
    """The tests of adding one group to the current model.

    Attributes:
        label: the group.
        extra_rank: independent columns it adds.
        f_statistic, p_value: the F test with effective samples.
        delta_bic: change of the information criterion (negative: better).
        rss_train, rss_test: effective residual sums of squares with the group.
        held_out_gain: decrease of the held-out effective RSS (positive: better).
        plausible, reason: the plausibility rule's verdict.
        eligible: whether every test passed.
        refused: every test but plausibility passed, and the group's own value is implausible
            (not only an effect already in, made implausible by it).
    """

    label: str
    extra_rank: float
    f_statistic: float
    p_value: float
    delta_bic: float
    rss_train: float
    rss_test: float
    held_out_gain: float
    plausible: bool
    reason: str
    eligible: bool
    refused: bool = False


@dataclass(frozen=True, eq=False)
class SelectionResult:
    """Forward selection's outcome.

    Attributes:
        selected: group labels in the order they entered.
        steps: the accepted step's evaluation, per selected group.
        rejected: the best candidate at the stop and why it did not enter (or None).
        stop_reason: why the selection stopped.
        level: the per-candidate significance level used.
        refused: per closed joint (index), the refused candidate that closed it (module doc).
    """

    selected: list[str]
    steps: list[GroupEvaluation]
    rejected: GroupEvaluation | None
    stop_reason: str
    level: float
    refused: dict[int, GroupEvaluation] = field(default_factory=dict)


#: plausibility(fit, labels) -> {label: (ok, reason)} for the groups of a fit.
PlausibilityCheck = Callable[[Design, Fit], dict[str, tuple[bool, str]]]
#: which candidates exclude each other (e.g. two Stribeck velocities of one joint).
ConflictCheck = Callable[[str, Sequence[str]], bool]


def _bic_change(rss_old: float, rss_new: float, extra: float, n_eff: float) -> float:
    if rss_new <= 0 or rss_old <= 0:
        return -math.inf if rss_new < rss_old else 0.0
    return n_eff * math.log(rss_new / rss_old) + extra * math.log(n_eff)


def noise_consistency(
    design: Design, fit: Fit, significance: float, tolerance: float
) -> tuple[bool, np.ndarray, np.ndarray]:
    """Whether each joint's residual (train and test) is consistent with the noise level.

    Returns:
        (all joints consistent, per-joint RMS / noise ratio, per-joint p-values of the chi^2
        variance test with effective samples).
    """
    n = design.y['train'].shape[1]
    chi2 = np.zeros(n)
    n_eff = np.zeros(n)
    for part in PARTS:
        residual = design.residual(fit, part)
        chi2 += design.weights * np.sum(residual**2, axis=0)
        n_eff += design.n_effective[part]
    ratio = np.sqrt(chi2 / np.maximum(n_eff, 1e-12))
    p_values = stats.chi2.sf(chi2, np.maximum(n_eff, 1.0))
    consistent = (p_values > significance) | (ratio <= tolerance)
    return bool(consistent.all()), ratio, p_values


def forward_select(
    design: Design,
    candidates: Sequence[str],
    plausibility: PlausibilityCheck,
    *,
    significance: float = 0.01,
    max_groups: int = 12,
    conflicts: ConflictCheck | None = None,
    noise_significance: float = 0.001,
    noise_tolerance: float = 1.25,
    last_resort: Callable[[str], bool] | None = None,
    start: Sequence[str] = (),
    deadline: float | None = None,
    joint_of: Callable[[str], int | None] | None = None,
) -> SelectionResult:
    """Add candidate groups one at a time while each passes every test (see the module doc).

    ``last_resort(label)`` marks general effects (every link's parameters) that enter only when
    no other candidate passes: they reproduce most specific effects' torques, and taken early
    they absorb an effect that one coefficient explains (a torque-constant error) and open
    trades (the link masses against every joint's torque scale) that nothing else settles.
    ``start``: groups already selected; the selection resumes from them (``steps`` then holds
    the new groups' only). ``deadline`` (``time.perf_counter()`` seconds): no step starts after
    it, and the stop reason says the budget ran out. ``joint_of(label)``: the index of the joint
    a candidate sits on (None: robot-wide); given, a refused candidate can close its joint
    (module doc).
    """
    n_eff = design.n_eff_train
    level = significance / max(len(candidates), 1)
    strict = level / 100.0
    selected: list[str] = list(start)
    steps: list[GroupEvaluation] = []
    current = design.fit(selected)
    stop_reason = 'reached the maximum number of effects'
    rejected: GroupEvaluation | None = None
    refused: dict[int, GroupEvaluation] = {}
    for _ in range(max(max_groups - len(selected), 0)):
        if deadline is not None and time.perf_counter() > deadline:
            stop_reason = BUDGET_STOP
            break
        evaluations = []
        for label in candidates:
            if label in selected or (conflicts is not None and conflicts(label, selected)):
                continue
            if joint_of is not None and joint_of(label) in refused:
                continue
            evaluations.append(
                _evaluate(design, current, label, plausibility, level=level, n_eff=n_eff)
            )
        if joint_of is not None:
            near = noise_tolerance * NEAR_NOISE
            closing = _closing(design, current, evaluations, joint_of, closed=refused, near=near)
            refused.update(closing)
            evaluations = [e for e in evaluations if joint_of(e.label) not in refused]
        eligible = [e for e in evaluations if e.eligible]
        for e in sorted(evaluations, key=lambda e: e.p_value)[:8]:
            _LOG.debug(
                'diagnosis: step %d: %s F = %.1f p = %.2g dBIC = %.1f held-out %+.1f %s',
                len(selected) + 1,
                e.label,
                e.f_statistic,
                e.p_value,
                e.delta_bic,
                e.held_out_gain,
                e.reason,
            )
        quiet, _, _ = noise_consistency(design, current, noise_significance, noise_tolerance)
        if last_resort is not None:
            eligible = [e for e in eligible if not last_resort(e.label)] or eligible
        best = min(eligible, key=lambda e: e.delta_bic) if eligible else None
        if best is None:
            rejected = min(evaluations, key=lambda e: e.p_value) if evaluations else None
            stop_reason = 'no remaining candidate passes every test'
            break
        if quiet and best.p_value > strict:
            rejected = best
            stop_reason = 'the residual is consistent with the noise level'
            break
        selected.append(best.label)
        steps.append(best)
        current = design.fit(selected)
        _LOG.info(
            'diagnosis: added %s (F = %.1f, p = %.2g, dBIC = %.1f)',
            best.label,
            best.f_statistic,
            best.p_value,
            best.delta_bic,
        )
    return SelectionResult(selected, steps, rejected, stop_reason, level, refused)


def _closing(
    design: Design,
    current: Fit,
    evaluations: Sequence[GroupEvaluation],
    joint_of: Callable[[str], int | None],
    *,
    closed: Mapping[int, GroupEvaluation],
    near: float,
) -> dict[int, GroupEvaluation]:
    """Per joint newly closed, the refused candidate that closes it (module doc).

    A refused candidate closes its joint when, added to ``current``, it leaves that joint's
    residual within ``near`` times the noise and its held-out gain on that joint is
    ``REFUSAL_DOMINANCE`` times that of every plausible candidate able to explain it (those on
    the joint and the robot-wide ones, such as a payload, that reach every joint): it fits what
    is left almost exactly, in a form the library would have to bend. A wild value that only
    soaks up several effects at once leaves more than the noise and closes nothing.
    """
    out: dict[int, GroupEvaluation] = {}
    for e in sorted((e for e in evaluations if e.refused), key=lambda e: -e.held_out_gain):
        joint = joint_of(e.label)
        if joint is None or joint in closed or joint in out:
            continue
        rivals = [x for x in evaluations if x.eligible and joint_of(x.label) in (joint, None)]
        best_rival = max((_joint_gain(design, current, x.label, joint) for x in rivals), default=0)
        if _joint_gain(design, current, e.label, joint) <= REFUSAL_DOMINANCE * best_rival:
            continue
        _, ratio, _ = noise_consistency(design, design.fit([*current.groups, e.label]), 1.0, 0.0)
        if ratio[joint] <= near:
            out[joint] = e
            _LOG.info(
                'diagnosis: %s fits what is left on joint %d but is refused (%s); the joint '
                'stays unexplained',
                e.label,
                joint + 1,
                e.reason,
            )
    return out


def _joint_gain(design: Design, current: Fit, label: str, joint: int) -> float:
    """How much adding ``label`` to ``current`` lowers one joint's held-out weighted RSS."""

    def rss(fit: Fit) -> float:
        residual = design.residual(fit, 'test')[:, joint]
        return float(design.weights[joint] * np.sum(residual**2))

    return rss(current) - rss(design.fit([*current.groups, label]))


def _evaluate(
    design: Design,
    current: Fit,
    label: str,
    plausibility: PlausibilityCheck,
    *,
    level: float,
    n_eff: float,
) -> GroupEvaluation:
    trial = design.fit([*current.groups, label])
    extra = trial.rank - current.rank
    f_stat, p_value = f_test(current.rss['train'], trial.rss['train'], extra, n_eff, trial.rank)
    delta_bic = _bic_change(current.rss['train'], trial.rss['train'], extra, n_eff)
    gain = current.rss['test'] - trial.rss['test']
    verdicts = plausibility(design, trial) if extra > 0 else {}
    bad = [(g, reason) for g, (ok, reason) in verdicts.items() if not ok]
    plausible = not bad
    reason = '; '.join(f'{g}: {r}' for g, r in bad)
    passes = extra > 0 and p_value < level and delta_bic < 0 and gain > 0
    eligible = passes and plausible
    return GroupEvaluation(
        label,
        extra,
        f_stat,
        p_value,
        delta_bic,
        trial.rss['train'],
        trial.rss['test'],
        gain,
        plausible,
        reason,
        eligible,
        refused=passes and any(g == label for g, _ in bad),
    )


def refused_records(
    design: Design, final: Fit, refused: Mapping[int, GroupEvaluation], joints: Sequence[str]
) -> list[dict[str, Any]]:
    """Per closed joint, the refused candidate, JSON-ready (``effects.json``, the report).

    Its values are fitted with ``final``'s groups; with them, the rule it fails and its tests.
    """
    out = []
    for joint, e in sorted(refused.items()):
        trial = design.fit([*final.groups, e.label])
        out.append({
            'joint': joints[joint],
            'label': e.label,
            'fitted': design.physical(trial, e.label).tolist(),
            'reason': e.reason,
            'held_out_gain': e.held_out_gain,
            'p_value': e.p_value,
        })  # fmt: skip
    return out


def rejected_record(selection: SelectionResult) -> dict[str, Any] | None:
    """The best candidate that did not enter, and why, JSON-ready; None if every one did."""
    r = selection.rejected
    if r is None:
        return None
    return {
        'label': r.label,
        'p_value': r.p_value,
        'level': selection.level,
        'delta_bic': r.delta_bic,
        'held_out_gain': r.held_out_gain,
        'plausible': r.plausible,
        'reason': r.reason,
    }


def selection_record(step: GroupEvaluation, test: BlockTest) -> dict[str, Any]:
    """The tests an effect passed when it entered, and its held-out block test, JSON-ready."""
    return {
        'f_statistic': step.f_statistic,
        'p_value': step.p_value,
        'delta_bic': step.delta_bic,
        'held_out_gain': step.held_out_gain,
        'columns': step.extra_rank,
        'held_out_blocks': {
            # None: too few blocks to judge (JSON has no NaN).
            'p_value_holm': None if np.isnan(test.p_value) else test.p_value,
            'n_blocks': test.n_blocks,
            'block_s': test.block_s,
            'gain_share': test.gain,
        },
    }
