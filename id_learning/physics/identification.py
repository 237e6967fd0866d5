"""Identify a physically consistent rigid-body and drive model from a recording's training part.

The model is ``physics.identified``'s: every body's inertial parameters theta, the rotor
inertias, the label gains (torque-constant scales), friction per joint and torque offsets.

- Through the label filter (the default preprocessing) every regressor column is computed on the
  controller's inputs and low-passed exactly like the labels (parallel filtering); the study's
  way the columns on the low-passed inputs meet the labels as they are.
- Rows are weighted by each joint's label-noise level, and count as the independent samples the
  filtered noise holds (its correlation time): the data term is a log-likelihood, so that the
  CAD prior (a Gaussian around the URDF's parameters, ``CadPrior``) and the data weigh each
  other honestly. Directions the excitation does not reach stay at the URDF's values.
- Physical consistency: each body's pseudo-inertia is kept positive semidefinite, a linear
  matrix inequality, solved with cvxpy and the Clarabel conic solver on the QR-reduced problem.
- The label gain multiplies the rigid-body torque, and load-dependent friction grows with it:
  both are bilinear, so they are linearised around the current estimate and the fit repeated
  (Gauss-Newton, ``iterations`` times). A Stribeck velocity is chosen per joint from candidates.
- Intervals: the posterior covariance of the last linearised problem (constraints inactive).
  The report gives the base parameters (the identifiable combinations, ``base_parameters``)
  with 95 % intervals, which of them the recording identifies and which stayed at the prior, and
  the condition number of the base regressor.
- Motor cogging, far above the label filter's band, is then found on the training part's
  unfiltered labels less the identified torque (``physics.cogging``); ``report['cogging']`` says
  per joint what was kept, or why nothing.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import linalg, stats

from id_learning.dataset.preprocess import Dataset
from id_learning.errors import DatasetError
from id_learning.physics.base_parameters import (
    BaseParameters,
    base_parameters,
    pseudo_inertia_basis,
)
from id_learning.physics.cogging import fit_cogging
from id_learning.physics.confirmation import (
    HELD_OUT_FRACTION,
    body_departures,
    body_label,
    claims,
    holdout_split,
    judge_claims,
)
from id_learning.physics.identification_problem import PINNED_STD, IdentificationConfig, Problem
from id_learning.physics.identification_search import choose_balancers, choose_stribeck
from id_learning.physics.identified import IdentifiedPhysics
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS
from id_learning.robot.config import RobotConfig
from id_learning.threads import single_blas_thread

__all__ = ['IdentificationConfig', 'identify']

_LOG = logging.getLogger(__name__)
#: Solver statuses whose solution is used.
SOLVED = ('optimal', 'optimal_inaccurate')
#: The share of a time budget in which the identification's optional steps may start.
_STEPS_SHARE = 0.5
#: A base parameter whose posterior std exceeds this share of its prior std stayed at the prior.
PRIOR_DOMINATED = 0.5


def _solve(problem: Problem, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """Minimise |A x - b|^2 + |(x - mean) / std|^2 (priors) with every pseudo-inertia PSD.

    Parameters held at their prior (``Layout.pin``) are constants here, not unknowns.

    Returns:
        (x, the posterior covariance of x (constraints inactive), the solver's status).
    """
    import cvxpy as cp
    from cvxpy.atoms.sum_squares import sum_squares

    layout = problem.layout
    mean = np.asarray(layout.prior_mean)
    std = np.asarray(layout.prior_std)
    free = std != PINNED_STD
    # The free unknowns' positions in u, by their position in x.
    position = np.cumsum(free) - 1
    has_prior = np.isfinite(std)[free]
    norms = np.linalg.norm(a[:, free], axis=0)
    # Scaled unknowns u: x = mean + s u, s the prior std or the column's inverse norm.
    s = np.where(has_prior, std[free], 1.0 / np.where(norms > 0, norms, 1.0))
    a_s = a[:, free] * s
    residual = b - a @ mean
    q, r = linalg.qr(a_s, mode='economic')
    z = q.T @ residual
    information = r.T @ r + np.diag(has_prior.astype(float))
    # Unexcited columns without a prior (friction of a joint that never moves) stay at zero.
    information += np.diag(np.where(np.diag(information) > 0, 0.0, 1.0))
    u = cp.Variable(int(free.sum()))
    # A whisper of ridge fixes the scaled unknowns of columns that are zero on this recording.
    # The objective on the scale of its value at the prior mean (labels a model misses badly
    # give 1e13 there, beyond a conic solver's tolerances); its minimiser is the same.
    scale = 1.0 / max(1.0, float(z @ z) / max(len(z), 1))
    objective = scale * (
        sum_squares(r @ u - z) + sum_squares(u[has_prior]) + 1e-9 * sum_squares(u)
    )
    theta_block = layout.blocks['theta']
    basis = pseudo_inertia_basis()
    constraints = []
    for body in range((theta_block.stop - theta_block.start) // N_INERTIAL_PARAMETERS):
        index = np.arange(theta_block.start, theta_block.start + 10) + 10 * body
        if not free[index].all():  # held at the URDF's values, which are physical
            continue
        # J(theta) = J(mean) + sum_k s_k u_k B_k, scaled by the body's mass for conditioning.
        mass = max(abs(mean[index[0]]), 1e-3)
        fixed = np.tensordot(mean[index], basis, axes=1) / mass
        terms = [u[position[k]] * (s[position[k]] / mass * basis[i]) for i, k in enumerate(index)]
        pseudo = fixed + sum(terms)
        constraints.append(0.5 * (pseudo + pseudo.T) >> 0)
    # A real drive has no negative rotor inertia and no friction that pushes.
    for name in ('rotor', *problem.laws):
        if name in layout.blocks:
            rows = position[np.arange(layout.blocks[name].start, layout.blocks[name].stop)]
            constraints.append(u[rows] >= -mean[layout.blocks[name]] / s[rows])
    payload = np.zeros(0, dtype=int)
    if 'payload' in layout.blocks:
        payload = np.arange(layout.blocks['payload'].start, layout.blocks['payload'].stop)
    if payload.size and free[payload].all():
        terms = [u[position[k]] * (s[position[k]] * basis[i]) for i, k in enumerate(payload)]
        pseudo = sum(terms)
        constraints.append(0.5 * (pseudo + pseudo.T) >> 0)
    constrained = cp.Problem(cp.Minimize(objective), constraints)
    with warnings.catch_warnings():
        # cvxpy warns of an inaccurate solution; its status says so, and the report keeps it.
        warnings.simplefilter('ignore', UserWarning)
        constrained.solve(solver=problem.config.solver)
    status = str(constrained.status)
    if u.value is None or status not in SOLVED:
        raise DatasetError(
            f'{problem.dataset.source}: the constrained identification found no solution '
            f'(solver {problem.config.solver}: {status})'
        )
    x = mean.copy()
    x[free] = mean[free] + s * np.asarray(u.value)
    covariance = np.zeros((len(layout), len(layout)))
    covariance[np.ix_(free, free)] = s[:, None] * np.linalg.inv(information) * s[None, :]
    return x, covariance, status


def _fit(
    problem: Problem,
    x: np.ndarray,
    stribeck: np.ndarray,
    iterations: int | None = None,
    *,
    grid: bool = True,
) -> tuple[np.ndarray, np.ndarray, str, np.ndarray]:
    """Linearise and solve (``config.iterations`` times); the nonlinear settings chosen on the way.

    Every solve but the last reweighs the rows by what the fit leaves (``Problem.reweight``).
    ``grid``: search the balancers' geometry on a grid first (else refine the one in use).

    Returns:
        (x, its covariance, the solver's status, the Stribeck velocities).
    """
    iterations = iterations or problem.config.iterations
    covariance = np.zeros((len(problem.layout), len(problem.layout)))
    status = 'optimal'
    for iteration in range(iterations):
        a, b = problem.design(x, stribeck)
        x, covariance, status = _solve(problem, a, b)
        if iteration < iterations - 1:
            problem.reweight((a @ x - b).reshape(problem.n, -1))
        if iteration < 2:
            if iteration == 0:
                stribeck = choose_stribeck(problem, x, stribeck)
            choose_balancers(problem, x, stribeck, grid=grid and iteration == 0)
    return x, covariance, status, stribeck


def _refit(problem: Problem, x: np.ndarray, stribeck: np.ndarray) -> np.ndarray:
    """One solve linearised around ``x`` (a claim's absence while judging it)."""
    return _solve(problem, *problem.design(x, stribeck))[0]


def _confirmed(
    problem: Problem,
    x: np.ndarray,
    stribeck: np.ndarray,
    deadline: float | None,
    *,
    grid: bool = True,
) -> tuple[Problem, np.ndarray, np.ndarray, dict[str, Any]]:
    """Judge the claims on the training part's held-out tail; the problem holding the confirmed.

    Past the ``deadline`` no claim is judged, so none is confirmed (the report says so).

    Returns:
        (the problem without the refused claims, a start for its fit, Stribeck velocities, the
        judgements for the report).
    """
    config = problem.config
    fit_rows, held_rows = holdout_split(problem)
    inner, held = problem.subset(fit_rows), problem.subset(held_rows)
    x, covariance, _, stribeck = _fit(inner, x, stribeck, grid=grid)
    to_judge = claims(inner, body_departures(inner, x, covariance))
    if _past(deadline):
        to_judge, judged = [], {}
        refused_unjudged = claims(inner, body_departures(inner, x, covariance))
    else:
        judged = judge_claims(
            inner, held, x, stribeck, to_judge, solve=_refit, significance=config.significance
        )
        refused_unjudged = []
    refused = [c for c in to_judge if not judged[c.label].confirmed] + refused_unjudged
    kept = problem.without_balancers([c.joint for c in refused if c.joint is not None])
    for j in kept.balancer_joints:
        kept.set_geometry(j, *inner.geometry[j])
    kept = kept.pinned([name for c in refused if c.kind != 'balancer' for name in c.names])
    kept.row_weight = inner.row_weight
    report = {
        'held_out_fraction': HELD_OUT_FRACTION,
        'held_out_s': float(len(held.rows) * problem.step * problem.dataset.period_s),
        'claims': [
            {'claim': c.label, 'kind': c.kind, **judged[c.label].to_dict()} for c in to_judge
        ],
        'unjudged': [c.label for c in refused_unjudged],
    }
    return kept, kept.layout.transfer(x, inner.layout), stribeck, report


def _unjudged_departures(
    problem: Problem, x: np.ndarray, covariance: np.ndarray, confirmation: dict[str, Any]
) -> bool:
    """Whether a body of the fit leaves its prior's 95 % range with no held-out judgement."""
    judged = {c['claim'] for c in confirmation['claims']}
    pinned = set(problem.layout.pinned_names())
    return any(
        entry['departs'] and body_label(entry) not in judged and f'body {k + 1} 0' not in pinned
        for k, entry in enumerate(body_departures(problem, x, covariance))
    )


def _merged(first: dict[str, Any], second: dict[str, Any]) -> dict[str, Any]:
    """The judgements of two rounds, the second's where both judged a claim."""
    claims = {c['claim']: c for c in first['claims']} | {c['claim']: c for c in second['claims']}
    return {
        **second,
        'rounds': 2,
        'claims': list(claims.values()),
        'unjudged': sorted(set(first['unjudged']) | set(second['unjudged'])),
    }


def _past(deadline: float | None) -> bool:
    return deadline is not None and time.perf_counter() > deadline


@single_blas_thread
def identify(
    dataset: Dataset,
    robot: RobotConfig,
    config: IdentificationConfig | None = None,
    *,
    deadline: float | None = None,
) -> IdentifiedPhysics:
    """Identify the rigid body and drives on the training part of ``dataset`` (module docstring).

    ``deadline`` (``time.perf_counter()`` seconds): past half the time to it, no claim is judged
    (none is then confirmed) and the final fit is linearised once; past it, no cogging is
    sought; ``report['cut_short']`` names what was cut.

    Raises:
        DatasetError: the training part is too short, or the solver finds no solution.
    """
    config = config or IdentificationConfig()
    start, cpu_start = time.perf_counter(), time.process_time()
    end = deadline
    # What follows the judging (the final fit) costs about what came before it: steps start
    # only in the first half of the budget, so that the whole stays within it.
    deadline = None if deadline is None else start + _STEPS_SHARE * (deadline - start)
    problem = Problem(dataset, robot, config)
    x = np.asarray(problem.layout.prior_mean, dtype=float)
    x = np.where(np.isfinite(x), x, 0.0)
    stribeck = np.full(problem.n, float(np.median(config.stribeck_velocities)))
    confirmation = None
    cut_short = []
    if config.confirm:
        problem, x, stribeck, confirmation = _confirmed(problem, x, stribeck, deadline)
        if confirmation['unjudged']:
            cut_short.append('the held-out judging of the claims (none confirmed)')
    iterations = None
    if _past(deadline):
        iterations = 1
        cut_short.append('the final fit (linearised once)')
    # After the judging the balancers keep the geometry found on the fit part, refined.
    x, covariance, status, stribeck = _fit(
        problem, x, stribeck, iterations, grid=confirmation is None
    )
    if confirmation is not None and _unjudged_departures(problem, x, covariance, confirmation):
        # A refused claim's torque went to bodies that stayed at their prior before: judge
        # them (and the claims kept) again on the model as it now is.
        if _past(deadline):
            cut_short.append('the judging of bodies that departed in the final fit')
        else:
            problem, x, stribeck, again = _confirmed(problem, x, stribeck, deadline, grid=False)
            confirmation = _merged(confirmation, again)
            x, covariance, status, stribeck = _fit(problem, x, stribeck, grid=False)
    layout, blocks, n = problem.layout, problem.layout.blocks, problem.n

    def block(name: str) -> np.ndarray:
        return x[blocks[name]].copy() if name in blocks else np.zeros(n)

    a, b = problem.design(x, stribeck)
    seconds = time.perf_counter() - start
    report = _report(problem, x, covariance=covariance, a=a, b=b, seconds=seconds)
    report['cpu_seconds'] = time.process_time() - cpu_start
    report['solver_status'] = status
    report['confirmation'] = confirmation
    report['cut_short'] = cut_short
    report['bodies'] = _bodies(problem, x, covariance, confirmation)
    if status != 'optimal':
        _LOG.warning(
            '%s: the identification solver ended %s (%s): the solution is kept; its '
            'constraints hold to the solver tolerance',
            dataset.source,
            status,
            config.solver,
        )
    _LOG.info('identified %d parameters in %.1f s', len(layout), seconds)
    physics = IdentifiedPhysics(
        robot=robot,
        target=dataset.target,
        theta=problem.theta(x),
        rotor=block('rotor'),
        gain=block('gain'),
        friction={law: block(law) for law in problem.laws},
        stribeck_velocity=stribeck,
        smoothing_velocity=config.smoothing_velocity,
        offset=block('offset'),
        delay_s=float(block('delay')[0]) if 'delay' in blocks else 0.0,
        balancer=problem.balancer_matrix(x),
        balancer_ratio=np.array([problem.geometry.get(j, (0.5, 0.0))[0] for j in range(n)]),
        balancer_phase=np.array([problem.geometry.get(j, (0.5, 0.0))[1] for j in range(n)]),
        report=report,
    )
    physics = _with_cogging(physics, dataset, config, end)
    physics.report['seconds'] = time.perf_counter() - start
    physics.report['cpu_seconds'] = time.process_time() - cpu_start
    return physics


def _with_cogging(
    physics: IdentifiedPhysics, dataset: Dataset, config: IdentificationConfig, end: float | None
) -> IdentifiedPhysics:
    """The model with the cogging the full-band stage finds (``physics.cogging``)."""
    report = physics.report
    if not config.cogging:
        report['cogging'] = {'skipped': 'switched off (identification.cogging)', 'joints': []}
        return physics
    if _past(end):
        report['cut_short'].append('the search for cogging (none sought)')
        report['cogging'] = {'skipped': 'past the time budget', 'joints': []}
        return physics
    found = fit_cogging(dataset, physics, config.cogging_periods)
    report['cogging'] = found.report
    return replace(physics, cogging=found.coefficients, cogging_periods=found.periods)


def _bodies(
    problem: Problem,
    x: np.ndarray,
    covariance: np.ndarray,
    confirmation: dict[str, Any] | None,
) -> list[dict[str, Any]]:
    """Each body's mass against its prior, and what the held-out part said of its departure."""
    judged = {c['claim']: c for c in (confirmation or {}).get('claims', [])}
    pinned = set(problem.layout.pinned_names())
    out = []
    for k, entry in enumerate(body_departures(problem, x, covariance)):
        label = body_label(entry)
        held = f'body {k + 1} 0' in pinned
        out.append({**entry, 'held_at_prior': held, 'held_out': judged.get(label)})
    return out


def _report(
    problem: Problem,
    x: np.ndarray,
    *,
    covariance: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    seconds: float,
) -> dict[str, Any]:
    """Base parameters with intervals, identifiability, drive values, residuals."""
    layout, blocks = problem.layout, problem.layout.blocks
    theta_rows = blocks['theta']
    rigid_rows = problem.rigid_block
    base: BaseParameters = base_parameters(problem.nominal, problem.robot.limits)
    # The bodies' total parameters (payload added to its carrying body) from x's rigid block.
    total = np.eye(theta_rows.stop - theta_rows.start, rigid_rows.stop - rigid_rows.start)
    if 'payload' in blocks:
        body = slice(10 * problem.payload_body, 10 * (problem.payload_body + 1))
        total[body, theta_rows.stop - theta_rows.start :] = problem.payload_map
    e = base.matrix @ total
    beta = e @ x[rigid_rows]
    beta0 = base.matrix @ problem.theta0
    std = np.sqrt(np.clip(np.diag(e @ covariance[rigid_rows, rigid_rows] @ e.T), 0.0, None))
    # Parameters without a prior (the payload's) make a base parameter's prior std infinite.
    prior_var = np.asarray(layout.prior_std)[rigid_rows] ** 2
    spread = np.zeros_like(e)
    np.multiply(e**2, prior_var[None, :], out=spread, where=e != 0)
    prior_std = np.sqrt(np.sum(spread, axis=1))
    z = float(stats.norm.ppf(0.975))
    # Condition number of the base regressor the recording gives (unit-norm columns).
    rigid = a[:, theta_rows][:, base.independent]
    norms = np.linalg.norm(rigid, axis=0)
    singular = np.linalg.svd(rigid / np.where(norms > 0, norms, 1.0), compute_uv=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else float('inf')
    residual = (a @ x - b).reshape(problem.n, -1)
    rms = np.sqrt(np.mean(residual**2, axis=1)) / problem.row_weight
    all_std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))

    def values(name: str) -> dict[str, list[float]] | None:
        if name not in blocks:
            return None
        rows = blocks[name]
        return {'value': x[rows].tolist(), 'std': all_std[rows].tolist()}

    return {
        'seconds': seconds,
        'samples': len(problem.rows),
        'row_step': problem.step,
        'noise_std_nm': problem.noise_std.tolist(),
        'training_rmse_nm': rms.tolist(),
        'condition_number': condition,
        'base_parameters': [
            {
                'name': name,
                'unit': unit,
                'value': float(beta[k]),
                'urdf': float(beta0[k]),
                'std': float(std[k]),
                'ci95': [float(beta[k] - z * std[k]), float(beta[k] + z * std[k])],
                # None: the combination holds a parameter without prior (the payload's).
                'prior_std': float(prior_std[k]) if np.isfinite(prior_std[k]) else None,
                'identified': bool(std[k] < PRIOR_DOMINATED * prior_std[k]),
            }
            for k, (name, unit) in enumerate(zip(base.names, base.units, strict=True))
        ],
        'base_matrix_rows': base.count,
        'drive': {
            name: values(name)
            for name in ('rotor', 'gain', 'delay', 'balancer', *problem.laws, 'offset')
            if name in blocks
        },
        'payload': None
        if 'payload' not in blocks
        else {'frame': problem.robot.payload_frame, **(values('payload') or {})},
        'balancers': [
            {
                'joint': problem.robot.joints[j],
                'ratio': problem.geometry[j][0],
                'phase_rad': problem.geometry[j][1],
            }
            for j in problem.balancer_joints
        ],
    }
