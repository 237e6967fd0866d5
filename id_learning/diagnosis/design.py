"""The weighted, normalised regression problem every diagnosis fit runs on, and its fits.

Rows are joint-samples; each joint's rows are weighted by d / (sigma_j^2 tau_j) (noise variance
sigma_j^2 of the filtered label, correlation time tau_j samples, every d-th sample kept), so a
residual sum of squares is in units of independent noise samples. ``selection`` chooses groups on
it.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ['PARTS', 'Design', 'Fit']

PARTS = ('train', 'test')


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
        out: np.ndarray = block / np.outer(norm, norm)
        return out

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
        out: np.ndarray = bread @ (per_block.T @ per_block) @ bread
        return out

    def residual(self, fit: Fit, part: str) -> np.ndarray:
        """(M, n) residual torque [N*m] (unweighted) of a fit on one part."""
        idx = self.indices(fit.groups)
        root = np.sqrt(self.weights)
        prediction = (self.matrix[part][:, idx] @ fit.theta).reshape(self.y[part].shape)
        out: np.ndarray = self._explained[part] - prediction / root
        return out

    def contribution(self, fit: Fit, group: str, part: str) -> np.ndarray:
        """(M, n) filtered torque [N*m] one group adds in a fit."""
        root = np.sqrt(self.weights)
        prediction = self.matrix[part][:, self.slices[group]] @ self.coefficients(fit, group)
        out: np.ndarray = prediction.reshape(self.y[part].shape) / root
        return out

    def weighted_columns(self, group: str, part: str = 'train') -> np.ndarray:
        """A group's weighted, normalised columns (rows = joint-samples)."""
        return self.matrix[part][:, self.indices([group])]


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
