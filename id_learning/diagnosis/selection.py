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
"""

from __future__ import annotations

import copy
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from id_learning.dataset.statistics import f_test

__all__ = [
    'BUDGET_STOP',
    'Design',
    'Fit',
    'GroupEvaluation',
    'SelectionResult',
    'forward_select',
]

_LOG = logging.getLogger(__name__)

PARTS = ('train', 'test')
#: The stop reason of a selection cut short by its time budget.
BUDGET_STOP = 'the time budget ran out'


@dataclass(frozen=True, eq=False)
class Fit:
    """A least-squares fit of some groups on the training part.

    Attributes:
        groups: group labels in the fit, in order.
        theta: coefficients of the normalised columns, concatenated in group order.
        rank: numerical rank of the fitted columns; with a prior on a group, its effective
            number of parameters trace((G + P)^-1 G).
        rss: {'train', 'test'} -> effective residual sums of squares.
        covariance: covariance of ``theta`` (normalised columns), scaled by the residual variance
            per effective sample (what the confidence intervals use).
        noise_covariance: the same for residuals of pure label noise (unit variance per
            effective sample): what estimation noise alone allows, whatever else is missing.
    """

    groups: tuple[str, ...]
    theta: np.ndarray
    rank: float
    rss: dict[str, float]
    covariance: np.ndarray
    noise_covariance: np.ndarray


class Design:
    """The weighted, normalised regression problem over every candidate group.

    Args:
        y: {'train', 'test'} -> (M, n) residual torques to explain [N*m] (filtered, kept rows).
        columns: group label -> {'train', 'test'} -> (M, n, k) filtered columns.
        weights: (n,) row weight of each joint (d / (sigma_j^2 tau_j)).
        n_effective: {'train', 'test'} -> (n,) effective samples per joint.
        priors: group label -> (k, k) prior precision of its physical coefficients (a Gaussian
            around zero, on the scale of effective samples): a fit of the group is then its
            posterior mean. For groups a CAD model already bounds (link parameters).
        offset: {'train', 'test'} -> (M, n) a known torque every fit holds beside its groups
            [N*m] (the constant of a linearisation, ``ResidualProblem.load_offset``); ``y``
            stays the residual without it.
    """

    def __init__(
        self,
        y: dict[str, np.ndarray],
        columns: dict[str, dict[str, np.ndarray]],
        weights: np.ndarray,
        n_effective: dict[str, np.ndarray],
        priors: dict[str, np.ndarray] | None = None,
        *,
        offset: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Stack, weight and normalise the columns; precompute the Gram matrices."""
        self.weights = np.asarray(weights, dtype=float)
        self.n_effective = {part: np.asarray(n_effective[part], dtype=float) for part in PARTS}
        root = np.sqrt(self.weights)
        self.y = {part: np.asarray(y[part], dtype=float) for part in PARTS}
        self._explained = {
            part: self.y[part] - offset[part] if offset is not None else self.y[part]
            for part in PARTS
        }
        self._yw = {part: (self._explained[part] * root).reshape(-1) for part in PARTS}
        self.slices: dict[str, slice] = {}
        blocks: dict[str, list[np.ndarray]] = {part: [] for part in PARTS}
        start = 0
        for label, parts in columns.items():
            k = parts['train'].shape[2]
            self.slices[label] = slice(start, start + k)
            start += k
            for part in PARTS:
                x = parts[part] * root[None, :, None]
                blocks[part].append(x.reshape(-1, k))
        n_columns = start
        self.matrix = {
            part: (np.hstack(blocks[part]) if blocks[part] else np.zeros((len(self._yw[part]), 0)))
            for part in PARTS
        }
        norms = np.linalg.norm(self.matrix['train'], axis=0)
        self.column_norm = np.where(norms > 0, norms, 1.0)
        for part in PARTS:
            self.matrix[part] = self.matrix[part] / self.column_norm
        self.gram = {part: self.matrix[part].T @ self.matrix[part] for part in PARTS}
        self.cross = {part: self.matrix[part].T @ self._yw[part] for part in PARTS}
        self.yy = {part: float(self._yw[part] @ self._yw[part]) for part in PARTS}
        self.n_columns = n_columns
        self.prior = np.zeros((n_columns, n_columns))
        self._set_priors(priors or {})

    def _set_priors(self, priors: dict[str, np.ndarray]) -> None:
        """Put prior precisions (physical units) in the normalised columns' units."""
        for label, precision in priors.items():
            if label in self.slices:
                block = self.slices[label]
                norm = self.column_norm[block]
                self.prior[block, block] = np.asarray(precision) / np.outer(norm, norm)

    def with_priors(self, priors: dict[str, np.ndarray]) -> Design:
        """The design with the groups in ``priors`` carrying those prior precisions instead."""
        out = copy.copy(self)
        out.prior = self.prior.copy()
        out._set_priors(priors)
        return out

    def pooled(
        self,
        project: Callable[[np.ndarray], np.ndarray] | None = None,
        nuisance: np.ndarray | None = None,
    ) -> Design:
        """The design whose training part holds the held-out part too; ``'test'`` is unchanged.

        The held-out part judges which effects enter; once the model is chosen its values are
        best read from every sample (fitted on the training part alone, a delay's or a friction
        level's variance is 1 / 0.7 of what the recording allows). ``project`` takes out of the
        held-out rows (M, n) or columns (M, n, k) the fit nuisances the training part was
        projected off (its standstills: ``ResidualProblem.pooled``); ``nuisance``: (n,) the
        effective samples they take per joint.
        """
        y, explained = self.y['test'], self._explained['test']
        yw, matrix, n_eff = self._yw['test'], self.matrix['test'], self.n_effective['test']
        if project is not None:
            rows, n = y.shape
            y, explained = project(y), project(explained)
            yw = project(yw.reshape(rows, n)).reshape(-1)
            matrix = project(matrix.reshape(rows, n, -1)).reshape(rows * n, -1)
            n_eff = np.maximum(n_eff - (0.0 if nuisance is None else nuisance), 1.0)
        out = copy.copy(self)

        def joined(parts: dict[str, np.ndarray], held_out: np.ndarray) -> dict[str, np.ndarray]:
            return {'train': np.concatenate([parts['train'], held_out]), 'test': parts['test']}

        def summed(parts: dict[str, Any], held_out: Any) -> dict[str, Any]:
            return {'train': parts['train'] + held_out, 'test': parts['test']}

        out.y, out._explained = joined(self.y, y), joined(self._explained, explained)
        out._yw, out.matrix = joined(self._yw, yw), joined(self.matrix, matrix)
        out.gram = summed(self.gram, matrix.T @ matrix)
        out.cross, out.yy = summed(self.cross, matrix.T @ yw), summed(self.yy, float(yw @ yw))
        out.n_effective = summed(self.n_effective, n_eff)
        return out

    @property
    def labels(self) -> list[str]:
        """Group labels in column order."""
        return list(self.slices)

    @property
    def n_eff_train(self) -> float:
        """Total effective samples of the training part."""
        return float(self.n_effective['train'].sum())

    def indices(self, groups: Sequence[str]) -> np.ndarray:
        """Column indices of the groups, in order."""
        if not groups:
            return np.zeros(0, dtype=int)
        return np.concatenate([np.arange(self.n_columns)[self.slices[g]] for g in groups])

    def fit(self, groups: Sequence[str]) -> Fit:
        """Least squares of the training part on the groups' columns (minimum norm if singular)."""
        idx = self.indices(groups)
        if not idx.size:
            rss = {part: self.yy[part] for part in PARTS}
            return Fit(tuple(groups), np.zeros(0), 0, rss, np.zeros((0, 0)), np.zeros((0, 0)))
        grams = {part: self.gram[part][np.ix_(idx, idx)] for part in PARTS}
        crosses = {part: self.cross[part][idx] for part in PARTS}
        theta, inverse, rank, rss = _solve(
            grams,
            crosses,
            self.yy,
            self.prior[np.ix_(idx, idx)],
            with_prior=bool(self.prior.any()),
        )
        covariance = inverse * self.residual_variance(rss['train'], rank)
        return Fit(tuple(groups), theta, rank, rss, covariance, inverse)

    def rss_with(
        self, groups: Sequence[str], label: str, columns: dict[str, np.ndarray]
    ) -> dict[str, float]:
        """A fit's rss over ``groups`` with ``label``'s columns replaced by ``columns``.

        ``columns``: per part (M, n, k), as wide as the group's. A setting's refinement tries
        many columns for one group: this costs their products with the design's columns, not a
        new design's whole Gram matrix.
        """
        idx = self.indices(groups)
        block = np.arange(self.n_columns)[self.slices[label]]
        position = np.flatnonzero(np.isin(idx, block))
        root = np.sqrt(self.weights)
        k = len(block)
        new = {part: (columns[part] * root[None, :, None]).reshape(-1, k) for part in PARTS}
        norms = np.linalg.norm(new['train'], axis=0)
        norms = np.where(norms > 0, norms, 1.0)
        grams, crosses = {}, {}
        for part in PARTS:
            x = new[part] / norms
            g = self.gram[part][np.ix_(idx, idx)].copy()
            products = (x.T @ self.matrix[part])[:, idx]
            g[position, :] = products
            g[:, position] = products.T
            g[np.ix_(position, position)] = x.T @ x
            c = self.cross[part][idx].copy()
            c[position] = x.T @ self._yw[part]
            grams[part], crosses[part] = g, c
        prior = self.prior[np.ix_(idx, idx)].copy()
        ratio = self.column_norm[block] / norms
        prior[np.ix_(position, position)] *= np.outer(ratio, ratio)
        return _solve(grams, crosses, self.yy, prior, with_prior=bool(self.prior.any()))[3]

    def residual_variance(self, rss_train: float, rank: float) -> float:
        """Training residual variance per effective degree of freedom of a fit's rss and rank."""
        return rss_train / max(self.n_eff_train - rank, 1.0)

    def physical(self, fit: Fit, group: str) -> np.ndarray:
        """A group's coefficients in the columns' physical units."""
        return self.coefficients(fit, group) / self.column_norm[self.slices[group]]

    def coefficients(self, fit: Fit, group: str) -> np.ndarray:
        """A group's coefficients in the normalised columns' units (``matrix``'s)."""
        position = self._position(fit, group)
        return fit.theta[position : position + self.slices[group].stop - self.slices[group].start]

    def _position(self, fit: Fit, group: str) -> int:
        position = 0
        for g in fit.groups:
            if g == group:
                return position
            position += self.slices[g].stop - self.slices[g].start
        raise KeyError(f'{group} is not in the fit {fit.groups}')

    def physical_covariance(self, fit: Fit, group: str, *, noise_only: bool = False) -> np.ndarray:
        """Covariance of a group's physical coefficients (``Fit.noise_covariance`` if asked)."""
        position = self._position(fit, group)
        k = self.slices[group].stop - self.slices[group].start
        norm = self.column_norm[self.slices[group]]
        source = fit.noise_covariance if noise_only else fit.covariance
        block = source[position : position + k, position : position + k]
        return block / np.outer(norm, norm)

    def sandwich_covariance(self, fit: Fit, blocks: np.ndarray) -> np.ndarray:
        """Covariance of a fit's coefficients from its training residual, blocks of time apart.

        The sandwich (X'WX + P)^-1 (sum_b s_b s_b') (X'WX + P)^-1 with s_b the score of block b:
        it holds whatever correlation and misfit the residual carries within blocks longer than
        its correlation, not only what the noise model assumes. ``blocks``: (M,) block index of
        each training row. In the normalised columns' units, like ``Fit.covariance``.
        """
        idx = self.indices(fit.groups)
        if not idx.size:
            return np.zeros((0, 0))
        x = self.matrix['train'][:, idx]
        error = self._yw['train'] - x @ fit.theta
        n = self.y['train'].shape[1]
        scores = (x * error[:, None]).reshape(-1, n, len(idx)).sum(axis=1)
        labels = np.unique(blocks, return_inverse=True)[1]
        per_block = np.zeros((int(labels.max()) + 1, len(idx)))
        np.add.at(per_block, labels, scores)
        bread = fit.noise_covariance
        return bread @ (per_block.T @ per_block) @ bread

    def residual(self, fit: Fit, part: str) -> np.ndarray:
        """(M, n) residual torque [N*m] (unweighted) of a fit on one part."""
        idx = self.indices(fit.groups)
        root = np.sqrt(self.weights)
        prediction = (self.matrix[part][:, idx] @ fit.theta).reshape(self.y[part].shape)
        return self._explained[part] - prediction / root

    def contribution(self, fit: Fit, group: str, part: str) -> np.ndarray:
        """(M, n) filtered torque [N*m] one group adds in a fit."""
        root = np.sqrt(self.weights)
        prediction = self.matrix[part][:, self.slices[group]] @ self.coefficients(fit, group)
        return prediction.reshape(self.y[part].shape) / root

    def weighted_columns(self, group: str, part: str = 'train') -> np.ndarray:
        """A group's weighted, normalised columns (rows = joint-samples)."""
        return self.matrix[part][:, self.indices([group])]


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


@dataclass(frozen=True, eq=False)
class SelectionResult:
    """Forward selection's outcome.

    Attributes:
        selected: group labels in the order they entered.
        steps: the accepted step's evaluation, per selected group.
        rejected: the best candidate at the stop and why it did not enter (or None).
        stop_reason: why the selection stopped.
        level: the per-candidate significance level used.
    """

    selected: list[str]
    steps: list[GroupEvaluation]
    rejected: GroupEvaluation | None
    stop_reason: str
    level: float


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


def _solve(
    grams: dict[str, np.ndarray],
    crosses: dict[str, np.ndarray],
    yy: dict[str, float],
    prior: np.ndarray,
    *,
    with_prior: bool,
) -> tuple[np.ndarray, np.ndarray, float, dict[str, float]]:
    """The regularised least squares of a fit from its Gram blocks (minimum norm if singular).

    Returns:
        (theta, (G + P)^+ in normalised units, the effective number of parameters, rss per part).
    """
    data = grams['train']
    values, vectors = np.linalg.eigh(data + prior)
    keep = values > 1e-10 * max(values.max(), 1e-300)
    inverse = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
    theta = inverse @ crosses['train']
    # With a prior, the effective number of parameters: trace((G + P)^-1 G).
    rank = float(np.trace(inverse @ data)) if with_prior else float(keep.sum())
    rss = {}
    for part in PARTS:
        value = yy[part] - 2.0 * theta @ crosses[part] + theta @ grams[part] @ theta
        rss[part] = max(float(value), 0.0)
    return theta, inverse, rank, rss


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
) -> SelectionResult:
    """Add candidate groups one at a time while each passes every test (see the module doc).

    ``last_resort(label)`` marks general effects (every link's parameters) that enter only when
    no other candidate passes: they reproduce most specific effects' torques, and taken early
    they absorb an effect that one coefficient explains (a torque-constant error) and open
    trades (the link masses against every joint's torque scale) that nothing else settles.
    ``start``: groups already selected; the selection resumes from them (``steps`` then holds
    the new groups' only). ``deadline`` (``time.perf_counter()`` seconds): no step starts after
    it, and the stop reason says the budget ran out.
    """
    n_eff = design.n_eff_train
    level = significance / max(len(candidates), 1)
    strict = level / 100.0
    selected: list[str] = list(start)
    steps: list[GroupEvaluation] = []
    current = design.fit(selected)
    stop_reason = 'reached the maximum number of effects'
    rejected: GroupEvaluation | None = None
    for _ in range(max(max_groups - len(selected), 0)):
        if deadline is not None and time.perf_counter() > deadline:
            stop_reason = BUDGET_STOP
            break
        evaluations = []
        for label in candidates:
            if label in selected or (conflicts is not None and conflicts(label, selected)):
                continue
            evaluations.append(
                _evaluate(design, current, label, plausibility, level=level, n_eff=n_eff)
            )
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
    return SelectionResult(selected, steps, rejected, stop_reason, level)


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
    eligible = extra > 0 and p_value < level and delta_bic < 0 and gain > 0 and plausible
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
    )
