"""Alias sets: effects this excitation cannot tell apart from a selected one.

An effect whose contribution another candidate reproduces within the noise, or that another
candidate on its joint replaces without a significant loss on either part, forms an alias set
with it (``find_aliases``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from id_learning.diagnosis.design import PARTS, Design, Fit
from id_learning.diagnosis.selection import PlausibilityCheck

__all__ = ['AliasSet', 'find_aliases', 'given_way', 'holds_columns']


@dataclass(frozen=True)
class AliasSet:
    """Effects this excitation cannot tell apart.

    Attributes:
        representative: the selected group kept in the model.
        members: every group that explains the same part equally well (representative first).
        canonical_correlation: canonical correlation of the representative's contribution with
            each member's filtered columns, after the other selected effects are projected out.
        unexplained: what a member leaves of the representative's contribution, in units of the
            residual variance per effective sample (0: reproduced exactly); for a member that
            fits as well in its place without reproducing it, the training fit lost there (its
            extra columns charged one residual variance each).
        further: alternatives that also pass but mimic less closely than the members listed
            (``closest``).
        separation: per listed alternative, the motion that would tell it from the
            representative (``separation.separating_motion``).
    """

    representative: str
    members: list[str]
    canonical_correlation: dict[str, float] = field(default_factory=dict)
    unexplained: dict[str, float] = field(default_factory=dict)
    further: int = 0
    separation: dict[str, dict[str, Any]] = field(default_factory=dict)

    def closest(self, count: int) -> AliasSet:
        """The set with only the ``count`` closest alternatives; the rest counted in ``further``.

        Dozens of alternatives tell a reader nothing but that the kept effect is small on this
        excitation; the few that mimic it best say what to tell apart next.
        """
        kept = self.alternatives()[:count]
        dropped = len(self.members) - 1 - len(kept)
        keep = {self.representative, *kept}
        return AliasSet(
            self.representative,
            [self.representative, *kept],
            {k: v for k, v in self.canonical_correlation.items() if k in keep},
            {k: v for k, v in self.unexplained.items() if k in keep},
            self.further + dropped,
            {k: v for k, v in self.separation.items() if k in keep},
        )

    def alternatives(self) -> list[str]:
        """The members other than the representative, the closest mimic first."""
        others = [m for m in self.members if m != self.representative]
        return sorted(others, key=lambda m: (self.unexplained.get(m, np.inf), m))

    def summary(self, shown: int = 2) -> str:
        """The representative and its ``shown`` closest alternatives, and how many more."""
        ranked = self.alternatives()
        more = len(ranked) - shown + self.further
        text = f'{self.representative} or {" or ".join(ranked[:shown])}'
        if more <= 0:
            return text
        return text + (
            f' (+{more} more that mimic it less closely: the kept effect is small on this '
            'excitation)'
        )


def find_aliases(
    design: Design,
    selected: Sequence[str],
    candidates: Sequence[str],
    plausibility: PlausibilityCheck,
    *,
    significance: float = 0.01,
    variants: Callable[[str, str], bool] | None = None,
    swappable: Callable[[str, str], bool] | None = None,
) -> list[AliasSet]:
    """For each selected group, the candidates that reproduce what it explains.

    Let c be the torque a selected group A contributes (filtered, weighted). A candidate B is an
    alias of A when B's columns, together with the other selected groups, reproduce c so closely
    that the difference is not significant: ||(I - P_{others, B}) c||^2 / s^2 below k_A times the
    F quantile (s^2 the residual variance per effective sample), on the training part and, with
    the same coefficients, on the held-out part; and the coefficients B needs for it are
    plausible, with the uncertainty that A's contribution carries. Only c is projected, never
    the noise: a large group earns nothing for the noise it could fit. The canonical
    correlation of c with B's columns (others projected out) is kept.
    ``variants(a, b)`` marks variants of one effect (two Stribeck velocities of one joint), which
    are no aliases of each other. Where ``swappable(a, b)``, B is an alias too when the model
    with B in A's place fits both parts not significantly worse: a candidate of another form
    (a balancer for a torque-constant error) may explain the data as well without reproducing
    the kept effect's own torque.
    """
    full = design.fit(list(selected))
    n_eff = design.n_eff_train
    n_eff_test = float(design.n_effective['test'].sum())
    dof = max(n_eff - full.rank, 1.0)
    scale = {
        'train': max(full.rss['train'] / dof, 1e-300),
        'test': max(full.rss['test'] / max(n_eff_test, 1.0), 1e-300),
    }
    out = []
    for a in selected:
        others = [g for g in selected if g != a]
        k_a = max(design.fit([*others, a]).rank - design.fit(others).rank, 1)
        critical = k_a * float(stats.f.isf(significance, k_a, dof))
        position_a = _positions(design, full, a)
        theta_a = full.theta[position_a]
        idx_a, idx_o = design.indices([a]), design.indices(others)
        # What the others alone leave of A's contribution (for the canonical correlations).
        beta_o, _ = _mimic(design.gram['train'], idx_o, idx_a, theta_a)
        total = _mimic_residual(design.gram['train'], idx_o, idx_a, theta_a, beta_o)
        members, correlations, unexplained = [a], {}, {}
        for b in candidates:
            if b in selected or (variants is not None and variants(a, b)):
                continue
            idx_b = design.indices([b])
            idx_s = np.concatenate([idx_o, idx_b])
            beta, kept = _mimic(design.gram['train'], idx_s, idx_a, theta_a)
            residual = {
                part: _mimic_residual(design.gram[part], idx_s, idx_a, theta_a, beta)
                for part in PARTS
            }
            if all(residual[part] / scale[part] <= critical for part in PARTS):
                # B would need exactly these coefficients to show what the data show; they
                # are as uncertain as A's contribution is.
                k_b = len(idx_b)
                gram = design.gram['train']
                mapping = (_inverse(gram[np.ix_(idx_s, idx_s)]) @ gram[np.ix_(idx_s, idx_a)])[
                    -k_b:
                ]
                covariance = mapping @ full.noise_covariance[position_a, position_a] @ mapping.T
                check = Fit((b,), beta[-k_b:], int(kept), {}, covariance, covariance)
                left = residual['train'] / scale['train']
            elif swappable is not None and swappable(a, b):
                # B in A's place fits both parts as well: the data cannot tell which it is.
                # Each column B has beyond A's fits one noise variance of the training part.
                check = design.fit([*others, b])
                extra = max(check.rank - full.rank, 0.0)
                loss = {part: (check.rss[part] - full.rss[part]) / scale[part] for part in PARTS}
                loss['train'] += extra
                if any(loss[part] > critical for part in PARTS):
                    continue
                left = max(loss['train'], 0.0)
            else:
                continue
            if not plausibility(design, check).get(b, (True, ''))[0]:
                continue
            members.append(b)
            unexplained[b] = float(left)
            correlations[b] = (
                float(math.sqrt(max(0.0, 1.0 - residual['train'] / total))) if total > 0 else 1.0
            )
        if len(members) > 1:
            out.append(AliasSet(a, members, correlations, unexplained))
    return out


def _positions(design: Design, fit: Fit, group: str) -> slice:
    position = 0
    for g in fit.groups:
        k = design.slices[g].stop - design.slices[g].start
        if g == group:
            return slice(position, position + k)
        position += k
    raise KeyError(group)


def _inverse(gram: np.ndarray) -> np.ndarray:
    if not gram.size:
        return gram
    values, vectors = np.linalg.eigh(gram)
    keep = values > 1e-10 * max(values.max(), 1e-300)
    out: np.ndarray = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
    return out


def _mimic(
    gram: np.ndarray, idx_s: np.ndarray, idx_a: np.ndarray, theta_a: np.ndarray
) -> tuple[np.ndarray, int]:
    """Coefficients of the columns idx_s that best reproduce the contribution X_a theta_a."""
    if not idx_s.size:
        return np.zeros(0), 0
    g_ss = gram[np.ix_(idx_s, idx_s)]
    inverse = _inverse(g_ss)
    rank = int(np.linalg.matrix_rank(g_ss)) if g_ss.size else 0
    return inverse @ (gram[np.ix_(idx_s, idx_a)] @ theta_a), rank


def _mimic_residual(
    gram: np.ndarray,
    idx_s: np.ndarray,
    idx_a: np.ndarray,
    theta_a: np.ndarray,
    beta: np.ndarray,
) -> float:
    """||X_a theta_a - X_s beta||^2 from a Gram matrix."""
    value = theta_a @ gram[np.ix_(idx_a, idx_a)] @ theta_a
    if idx_s.size:
        value += -2.0 * beta @ (gram[np.ix_(idx_s, idx_a)] @ theta_a)
        value += beta @ gram[np.ix_(idx_s, idx_s)] @ beta
    return max(float(value), 0.0)


def given_way(
    before: list[AliasSet], stand_in: dict[str, str | None], now: list[AliasSet]
) -> list[AliasSet]:
    """``now`` with each spring that gave way to a stand-in among the stand-in's alternatives.

    The spring stays an alternative of what took its place: the data could not tell them apart,
    and a robot-wide stand-in (the link parameters) has no joint to find it by again.
    """
    out = list(now)
    for alias in before:
        taker = stand_in.get(alias.representative)
        if taker is None:
            continue
        led = next((a for a in out if a.representative == taker), None)
        members = [taker, *(m for m in alias.members if m != taker)]
        if led is not None:
            members = [*led.members, *(m for m in members if m not in led.members)]
            out.remove(led)
        correlation = {**alias.canonical_correlation, **(led.canonical_correlation if led else {})}
        unexplained = {**alias.unexplained, **(led.unexplained if led else {})}
        out.append(AliasSet(taker, members, correlation, unexplained))
    return out


def holds_columns(general: np.ndarray, special: np.ndarray) -> bool:
    """Whether ``general``'s columns (..., k) span every one of ``special``'s, and more.

    Such an effect is a generalisation of the other (a torsion spring's constant is a torque
    offset), not an alternative to it: the data can never prefer the special one by fit.
    """
    x_general = general.reshape(-1, general.shape[-1])
    x_special = special.reshape(-1, special.shape[-1])
    if x_general.shape[1] <= x_special.shape[1] or not x_special.any():
        return False
    fit, *_ = np.linalg.lstsq(x_general, x_special, rcond=None)
    misfit = np.linalg.norm(x_general @ fit - x_special)
    return bool(misfit <= 1e-9 * np.linalg.norm(x_special))
