"""The identification's nonlinear settings: Stribeck velocities and balancer geometries.

Each is chosen with the linear parameters refitted: a Stribeck velocity per joint from
candidates, a balancer's geometry (arm ratio, phase) on a coarse grid and then refined by
Gauss-Newton with the linear parameters projected out (variable projection). No search here is
derivative-free, and each costs a few filter passes over the recording.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from id_learning.physics.balancer import (
    BALANCER_TERMS,
    balancer_basis,
    balancer_basis_derivatives,
)
from id_learning.physics.identification_problem import Layout, Problem

__all__ = ['NormalEquations', 'Refit', 'choose_balancers', 'choose_stribeck', 'joint_system']


def choose_stribeck(problem: Problem, x: np.ndarray, stribeck: np.ndarray) -> np.ndarray:
    """Per joint, the candidate Stribeck velocity whose refit leaves the least residual.

    Only the joint's own drive columns are refitted (ordinary least squares), the rest held.
    """
    hump = problem.hump_law
    if hump is None:
        return stribeck
    blocks, n, rows = problem.layout.blocks, problem.n, len(problem.rows)
    best = stribeck.copy()
    a, b = problem.design(x, stribeck)
    a, b = a.reshape(n, rows, -1), b.reshape(n, rows)
    local = [blocks[name].start for name in ('rotor', 'gain', *problem.laws, 'offset')
             if name in blocks]  # fmt: skip
    for j in range(n):
        columns = [k + j for k in local]
        held = np.delete(np.arange(a.shape[2]), columns)
        target = b[j] - a[j][:, held] @ x[held]
        errors = []
        for vs in problem.config.stribeck_velocities:
            trial = stribeck.copy()
            trial[j] = vs
            column = problem.friction(x, trial, (hump,))[hump][:, j]
            design = a[j][:, columns].copy()
            design[:, columns.index(blocks[hump].start + j)] = column * problem.row_weight[j]
            coefficients, *_ = np.linalg.lstsq(design, target, rcond=None)
            errors.append(float(np.sum((design @ coefficients - target) ** 2)))
        best[j] = problem.config.stribeck_velocities[int(np.argmin(errors))]
    return best


def joint_system(
    problem: Problem, x: np.ndarray, stribeck: np.ndarray, j: int, local: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Joint j's rows: its local columns (weighted) and the target with the rest held at x."""
    a, b = problem.design(x, stribeck)
    rows = len(problem.rows)
    a, b = a.reshape(problem.n, rows, -1)[j], b.reshape(problem.n, rows)[j]
    held = np.delete(np.arange(a.shape[1]), local)
    return a[:, local], b - a[:, held] @ x[held]


@dataclass(eq=False)
class NormalEquations:
    """The regularised normal equations of (A, b), columns scaled to unit norm."""

    a: np.ndarray
    b: np.ndarray
    scale: np.ndarray
    gram: np.ndarray
    right: np.ndarray
    precision: np.ndarray
    mean: np.ndarray

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, layout: Layout) -> NormalEquations:
        """The equations of the system (a, b) with the layout's priors."""
        mean = np.asarray(layout.prior_mean)
        std = np.asarray(layout.prior_std)
        precision = np.where(np.isfinite(std), 1.0 / std**2, 0.0)
        scale = np.linalg.norm(a, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        scaled = a / scale
        # In the scaled unknowns u = x * scale: A x = (A / scale) u.
        right = scaled.T @ b + precision * mean / scale
        return cls(scaled, b, scale, scaled.T @ scaled, right, precision, mean)

    def misfit_with(self, columns: np.ndarray, rows: slice, new: np.ndarray) -> float:
        """The minimised objective with ``columns`` replaced by ``new`` on ``rows``.

        ``new`` is zero outside ``rows``; the objective is up to the constant b^T b.
        """
        return self.solve_with(columns, rows, new).misfit

    def solve_with(self, columns: np.ndarray, rows: slice, new: np.ndarray) -> Refit:
        """The regularised refit with ``columns`` replaced by ``new`` on ``rows`` (``Refit``)."""
        new = new / self.scale[columns]
        g, r = self.gram.copy(), self.right.copy()
        cross = self.a[rows].T @ new
        g[:, columns] = cross
        g[columns, :] = cross.T
        g[np.ix_(columns, columns)] = new.T @ new
        r[columns] = new.T @ self.b[rows]
        regular = g + np.diag(self.precision / self.scale**2) + 1e-12 * np.eye(len(g))
        u = np.linalg.solve(regular, r)
        prior = np.sum(self.precision * (u / self.scale - self.mean) ** 2)
        local = self.a[rows].copy()
        local[:, columns] = new
        return Refit(
            misfit=float(u @ g @ u - 2 * u @ r + prior),
            x=u / self.scale,
            residual=local @ u - self.b[rows],
            design=local,
            regular=regular,
        )


@dataclass(frozen=True, eq=False)
class Refit:
    """One regularised refit of ``NormalEquations.solve_with``.

    Attributes:
        misfit: the minimised objective, up to the constant b^T b.
        x: the parameters in physical units.
        residual: the weighted residual on the replaced rows.
        design: the scaled design of those rows, the new columns in place.
        regular: the regularised normal matrix in scaled units.
    """

    misfit: float
    x: np.ndarray
    residual: np.ndarray
    design: np.ndarray
    regular: np.ndarray


#: Gauss-Newton steps that refine a balancer's geometry, and the smallest step that counts.
_GEOMETRY_STEPS = 12
_GEOMETRY_TOLERANCE = 1e-5
#: The arm ratio stays in this range: towards 0 the three columns merge into sin and sin 2 of
#: the angle, towards 1 the balancer is a point at upright.
RATIO_RANGE = (0.05, 0.98)


def choose_balancers(
    problem: Problem, x: np.ndarray, stribeck: np.ndarray, *, grid: bool = True
) -> None:
    """Per balancer joint, the geometry whose refit leaves the least (regularised) misfit.

    Every parameter is refitted for each geometry (the priors included, the constraints left
    out), because a balancer trades against the first moment of the link it holds. A coarse grid
    of ratios and phases, its columns filtered in one pass, gives the start; Gauss-Newton on the
    basis's analytic derivatives with the linear parameters projected out (variable projection,
    Kaufman's step) refines ratio and phase together: an encoder zero error shifts the phase by
    milliradians. The normal equations change in the joint's three balancer columns only.
    Without ``grid`` the refinement starts from the geometry in use (a later linearisation).
    """
    layout, config = problem.layout, problem.config
    for j in problem.balancer_joints:
        equations = NormalEquations.of(*problem.design(x, stribeck), layout)
        first = layout.blocks['balancer'].start + problem.balancer_joints.index(j) * BALANCER_TERMS
        columns = np.arange(first, first + BALANCER_TERMS)
        start = problem.geometry[j]
        if grid:
            rows = slice(j * len(problem.rows), (j + 1) * len(problem.rows))
            points = [(r, p) for r in config.balancer_ratios for p in config.balancer_phases]
            q = problem.q[:, j]
            stacked = np.concatenate([balancer_basis(q, r, p) for r, p in points], axis=1)
            filtered = problem.kept_columns(stacked, j) * problem.row_weight[j]
            misfits = [
                equations.misfit_with(columns, rows, filtered[:, 3 * k : 3 * k + 3])
                for k in range(len(points))
            ]
            start = points[int(np.argmin(misfits))]
        problem.set_geometry(j, *_refine_geometry(problem, equations, j, columns, start))


def _refine_geometry(
    problem: Problem,
    equations: NormalEquations,
    j: int,
    columns: np.ndarray,
    start: tuple[float, float],
) -> tuple[float, float]:
    """Gauss-Newton (variable projection) on joint j's balancer (ratio, phase) from ``start``."""
    q, weight = problem.q[:, j], problem.row_weight[j]
    rows = slice(j * len(problem.rows), (j + 1) * len(problem.rows))

    def evaluate(geometry: np.ndarray) -> tuple[Refit, np.ndarray]:
        ratio, phase = float(geometry[0]), float(geometry[1])
        derivatives = balancer_basis_derivatives(q, ratio, phase).reshape(len(q), -1)
        both = np.concatenate([balancer_basis(q, ratio, phase), derivatives], axis=1)
        filtered = problem.kept_columns(both, j) * weight
        refit = equations.solve_with(columns, rows, filtered[:, :BALANCER_TERMS])
        return refit, filtered[:, BALANCER_TERMS:].reshape(-1, BALANCER_TERMS, 2)

    low, high = RATIO_RANGE
    geometry = np.array(start, dtype=float)
    refit, derivative = evaluate(geometry)
    for _ in range(_GEOMETRY_STEPS):
        coefficients = refit.x[columns]
        # The residual's Jacobian: the columns' derivatives times the balancer's coefficients,
        # less what the refitted linear parameters take of them (Kaufman's projection).
        moved = np.einsum('tkm,k->tm', derivative, coefficients)
        taken = refit.design.T @ moved
        hessian = 2.0 * (moved.T @ moved - taken.T @ np.linalg.solve(refit.regular, taken))
        gradient = 2.0 * moved.T @ refit.residual
        damping = 1e-9 * np.trace(hessian) + 1e-300
        step = -np.linalg.solve(hessian + damping * np.eye(2), gradient)
        improved = False
        for _ in range(8):  # halve the step until the misfit falls
            trial = geometry + step
            trial[0] = float(np.clip(trial[0], low, high))
            trial_refit, trial_derivative = evaluate(trial)
            if trial_refit.misfit < refit.misfit:
                improved = True
                break
            step = step / 2
        if not improved:
            break
        moved_by = float(np.max(np.abs(trial - geometry)))
        geometry, refit, derivative = trial, trial_refit, trial_derivative
        if moved_by < _GEOMETRY_TOLERANCE:
            break
    return float(geometry[0]), float(geometry[1])
