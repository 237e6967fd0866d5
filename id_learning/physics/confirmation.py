"""What the CAD model does not hold enters the identified physics where held-out data confirm it.

A balancer, a payload, and a body whose mass or centre of mass leaves its CAD prior's 95 % range
each claim something the URDF does not say. On a real robot whose forms differ from the model's
(a joint's friction, an elastic gear, a cable), such parameters fit the training part by
absorbing what the model lacks: a 3 kg link made 56 kg, balancers on joints that have none.
So each is judged as the diagnosis judges an effect (``dataset.blocks``): the training part's
tail is held out, the model is fitted on the rest with and without the claim (held at its prior
mean: a balancer or payload at zero, a body at its URDF values), and the held-out gain is tested
over blocks of time, Holm-corrected over the claims. What the held-out blocks do not confirm is
held at its prior in the final fit on the whole training part, and the report says which claims
were judged, with their gain and p.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from id_learning.dataset.blocks import (
    MIN_BLOCKS,
    block_gains,
    block_ids,
    block_length_s,
    holm,
    one_sided_p,
)
from id_learning.dataset.statistics import f_test, integrated_autocorrelation
from id_learning.physics.balancer import BALANCER_TERMS
from id_learning.physics.identification_problem import Problem
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS

__all__ = [
    'HELD_OUT_FRACTION',
    'Claim',
    'Judgement',
    'body_departures',
    'body_label',
    'claims',
    'holdout_split',
    'judge_claims',
]

#: The share of each recording's training part held out to judge the claims.
HELD_OUT_FRACTION = 0.3
#: A body departs from its prior when its mass leaves the prior's 95 % range, or its first
#: moment leaves the 95 % ellipsoid (three components, chi-square).
_MASS_Z = float(stats.norm.ppf(0.975))
_FIRST_MOMENT_Z = math.sqrt(float(stats.chi2.ppf(0.95, 3)))

#: Fits (problem, x, stribeck) -> x that the judging makes: the identification's solver.
Solver = Callable[[Problem, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Claim:
    """Something the CAD model does not hold, and the parameters that hold it."""

    label: str
    kind: str  # 'balancer', 'payload' or 'body'
    names: tuple[str, ...]
    joint: int | None = None  # a balancer's joint


@dataclass(frozen=True)
class Judgement:
    """A claim judged on the held-out blocks.

    Attributes:
        p_value: one-sided p of 'no held-out gain', Holm-corrected over the claims.
        gain: mean gain over the blocks (per block, the share of each joint's mean square
            without the claim that it removes, summed over joints).
        n_blocks: held-out blocks.
        block_s: their length [s].
        confirmed: the gain is significant at the identification's level.
        test: 'blocks' (a t test over the blocks' gains), or 'effective samples' where the
            held-out part holds fewer than ``MIN_BLOCKS`` blocks (an F test of its residual
            sums in independent samples: each joint's samples over its correlation time).
        implausible: why a claim the held-out part supports is no such hardware (a balancer
            that adds to gravity on average); empty when it is plausible.
    """

    p_value: float
    gain: float
    n_blocks: int
    block_s: float
    confirmed: bool
    test: str = 'blocks'
    implausible: str = ''

    def to_dict(self) -> dict[str, float | int | bool | str | None]:
        """JSON-ready, nan as None."""
        return {
            'p_value_holm': None if math.isnan(self.p_value) else self.p_value,
            'gain': self.gain,
            'blocks': self.n_blocks,
            'block_s': self.block_s,
            'test': self.test,
            'confirmed': self.confirmed,
            'implausible': self.implausible or None,
        }


def holdout_split(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Positions into ``problem.rows`` that fit, and the held-out tail of each recording.

    A gap of one filter time constant (1 / the lowest cut-off) between the two keeps the
    zero-phase filter from carrying the held-out labels' noise into the fit.
    """
    rows, dataset = problem.rows, problem.dataset
    segments = dataset.extra.get('segments') or []
    ranges = [tuple(s['train']) for s in segments if 'train' in s]
    if not ranges:
        ranges = [(int(rows[0]), int(rows[-1]) + 1)]
    gap = 1.0 / float(np.min(dataset.cutoff_hz)) / dataset.period_s
    fit = np.zeros(len(rows), dtype=bool)
    held = np.zeros(len(rows), dtype=bool)
    for start, stop in ranges:
        inside = np.flatnonzero((rows >= start) & (rows < stop))
        if len(inside) == 0:
            continue
        first, last = rows[inside[0]], rows[inside[-1]]
        cut = first + (1.0 - HELD_OUT_FRACTION) * (last - first)
        held[inside[rows[inside] >= cut]] = True
        fit[inside[rows[inside] < cut - gap]] = True
    return np.flatnonzero(fit), np.flatnonzero(held)


def body_departures(
    problem: Problem, x: np.ndarray, covariance: np.ndarray
) -> list[dict[str, object]]:
    """Per body, its mass and first moment against the CAD prior, with 95 % intervals.

    A body departs when its mass's z-score leaves +-1.96 or its first moment's distance from
    the prior (in prior stds) leaves the 95 % ellipsoid.
    """
    layout = problem.layout
    start = layout.blocks['theta'].start
    mean, std = np.asarray(layout.prior_mean), np.asarray(layout.prior_std)
    joints = list(problem.nominal.model.names[1:])
    out: list[dict[str, object]] = []
    for body in range(len(problem.theta0) // N_INERTIAL_PARAMETERS):
        k = start + N_INERTIAL_PARAMETERS * body
        mass, mass0, mass_std = float(x[k]), float(mean[k]), float(std[k])
        interval = 1.96 * math.sqrt(max(float(covariance[k, k]), 0.0))
        first = x[k + 1 : k + 4] - mean[k + 1 : k + 4]
        first_z = float(np.linalg.norm(first / std[k + 1 : k + 4]))
        mass_z = (mass - mass0) / mass_std
        out.append({
            'body': f'body {body + 1}',
            'joint': joints[body],
            'mass_kg': mass,
            'mass_ci95_kg': [mass - interval, mass + interval],
            'urdf_mass_kg': mass0,
            'prior_std_kg': mass_std,
            'mass_z': mass_z,
            'first_moment_z': first_z,
            'departs': bool(abs(mass_z) > _MASS_Z or first_z > _FIRST_MOMENT_Z),
        })  # fmt: skip
    return out


def body_label(entry: dict[str, object]) -> str:
    """A body's claim label from its ``body_departures`` entry, e.g. 'body 2 (joint_2)'."""
    return f'{entry["body"]} ({entry["joint"]})'


def claims(problem: Problem, departures: list[dict[str, object]]) -> list[Claim]:
    """The balancers, the payload and the departing bodies of ``problem``, to be judged."""
    layout, joints = problem.layout, problem.robot.joints
    out = []
    for j in problem.balancer_joints:
        names = tuple(f'balancer {joints[j]} c{k}' for k in range(BALANCER_TERMS))
        out.append(Claim(f'balancer on {joints[j]}', 'balancer', names, joint=j))
    if 'payload' in layout.blocks:
        out.append(Claim('payload', 'payload', tuple(layout.names[layout.blocks['payload']])))
    for body, entry in enumerate(departures):
        if entry['departs']:
            names = tuple(f'body {body + 1} {p}' for p in range(N_INERTIAL_PARAMETERS))
            out.append(Claim(body_label(entry), 'body', names))
    pinned = set(layout.pinned_names())
    return [claim for claim in out if not set(claim.names) <= pinned]


def judge_claims(
    inner: Problem,
    held: Problem,
    x: np.ndarray,
    stribeck: np.ndarray,
    to_judge: list[Claim],
    *,
    solve: Solver,
    significance: float,
) -> dict[str, Judgement]:
    """Each claim's held-out gain: the fit on ``inner`` with and without it, scored on ``held``.

    ``x`` is the fit with every claim on ``inner``; a claim's absence is one refit with its
    parameters held at their prior mean, linearised around ``x``.
    """
    for j in inner.balancer_joints:
        held.set_geometry(j, *inner.geometry[j])

    def residual(problem: Problem, estimate: np.ndarray) -> np.ndarray:
        a, b = problem.design(estimate, stribeck)
        out: np.ndarray = (a @ estimate - b).reshape(problem.n, -1).T
        return out

    with_all = residual(held, x)
    seconds_per_row = inner.step * held.dataset.period_s
    block_s = block_length_s(with_all, seconds_per_row)
    times = held.dataset.stamps_ns[held.rows] * 1e-9
    blocks = block_ids(times - times[0], block_s, seconds_per_row)
    raw: dict[str, tuple[float, float, int]] = {}
    for claim in to_judge:
        without = solve(inner.pinned(claim.names), x, stribeck)
        worse = residual(held.pinned(claim.names), without)
        total = block_gains(worse, with_all, blocks).sum(axis=1)
        p = one_sided_p(total)
        if math.isnan(p):
            p = _effective_sample_p(worse, with_all, len(claim.names))
        raw[claim.label] = (p, float(np.mean(total)), len(total))
    adjusted = holm({label: value[0] for label, value in raw.items()})
    test = 'blocks' if len(np.unique(blocks)) >= MIN_BLOCKS else 'effective samples'
    why = {c.label: _implausible(inner, x, c) for c in to_judge}
    return {
        label: Judgement(
            p_value=adjusted[label],
            gain=gain,
            n_blocks=count,
            block_s=block_s,
            confirmed=bool(adjusted[label] < significance) and not why[label],
            test=test,
            implausible=why[label],
        )
        for label, (_, gain, count) in raw.items()
    }


def _implausible(problem: Problem, x: np.ndarray, claim: Claim) -> str:
    """Why a claim is no such hardware whatever the held-out gain; empty when plausible.

    A balancer exists to carry a link's weight: over the recording its torque must take load
    off gravity's (the URDF's gravity torque on its joint) on average. One that adds to it
    stands in for something else the model lacks (a sensor's offset that turns with the joint,
    a link's mass distribution), as on a Panda's third joint, whose 0.1 N*m 'balancer' beside
    9 N*m of gravity the held-out part supported.
    """
    if claim.kind != 'balancer' or claim.joint is None:
        return ''
    j = claim.joint
    torque = problem.balancer_basis[j] @ problem.balancer_matrix(x)[j]
    gravity = problem.nominal_gravity[:, j]
    if float(np.mean(torque * gravity)) < 0.0:
        return ''
    return 'its torque adds to gravity on average: no balancer carries weight that way'


def _effective_sample_p(worse: np.ndarray, better: np.ndarray, parameters: int) -> float:
    """The p of 'no held-out gain' in independent samples (too few blocks for a t test).

    Each joint's residual sums are put in units of its independent samples (its samples over
    the better model's correlation time, the better model's residual variance as the unit), and
    an F test asks whether the worse model's excess could be chance.
    """
    n_eff = np.array(
        [len(better) / integrated_autocorrelation(better[:, j]) for j in range(better.shape[1])]
    )
    power = np.mean(better**2, axis=0)
    used = power > 0
    large = float(np.sum(n_eff[used]))
    small = float(np.sum(n_eff[used] * np.mean(worse[:, used] ** 2, axis=0) / power[used]))
    return f_test(small, large, parameters, large, 0.0)[1]
