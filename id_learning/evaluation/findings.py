"""The study's findings checked on our numbers: section (e) of the report.

Holds the friction share that decides the high-friction axes from the data, and one function
per finding rule, so that each rule reads on its own; ``check_findings`` picks the rules of a
label case. Markdown and figures live elsewhere (``evaluation.report``, ``report_tables``,
``report_figures``); this module only decides.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from id_learning.evaluation.data_summary import rms
from id_learning.evaluation.study import MODEL_LABELS, STUDY_FINDINGS
from id_learning.physics.friction import coulomb

__all__ = [
    'DISSIPATION_FREE_SHARE',
    'FRICTION_SMOOTHING_VELOCITY',
    'GAP_RECOVERED_FRACTION',
    'HIGH_FRICTION_SHARE',
    'LAGRANGIAN_COMPETITIVE_RATIO',
    'Decision',
    'Finding',
    'check_findings',
    'friction_share',
    'high_friction_axes',
    'model_label',
]

#: An axis is high-friction when friction carries at least this share of its label's RMS.
HIGH_FRICTION_SHARE = 0.5
#: Velocity scale of the smoothed sign in the friction regression [rad/s].
FRICTION_SMOOTHING_VELOCITY = 0.01
#: LNN+MLP "recovers most of the gap" when it closes at least this share of LNN's gap.
GAP_RECOVERED_FRACTION = 0.5
#: Lagrangian networks are "competitive" when their error is at most this multiple of RNEA+MLP's.
LAGRANGIAN_COMPETITIVE_RATIO = 1.25
#: Below this friction share a label counts as free of dissipation.
DISSIPATION_FREE_SHARE = 0.1

#: A rule's outcome: whether it holds, the numbers, and the reasons if it does not.
Decision = tuple[bool, str, list[str]]


@dataclass(frozen=True)
class Finding:
    """One of the study's findings checked on our numbers.

    Attributes:
        key: short identifier.
        claim: the study's claim.
        rule: how it is decided here.
        holds: True, False, or None when it could not be checked.
        evidence: the numbers behind the verdict.
        why: when it does not hold (or was not checked), the reasons found.
        caveat: what may change the verdict either way (models stopped by their time budget).
    """

    key: str
    claim: str
    rule: str
    holds: bool | None
    evidence: str
    why: str = ''
    caveat: str = ''

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return dict(self.__dict__)


def model_label(kind: str) -> str:
    """A model kind's name as the report writes it (RNEA+MLP for 'rnea_mlp')."""
    return MODEL_LABELS.get(kind, kind)


def friction_share(
    tau: np.ndarray,
    remainder: np.ndarray,
    v: np.ndarray,
    smoothing_velocity: float = FRICTION_SMOOTHING_VELOCITY,
) -> np.ndarray:
    """Share of each joint's label RMS that is friction, (n,) [-].

    Friction is estimated by least squares on the nominal remainder (label minus URDF rigid body
    and datasheet rotor inertia): per joint ``r = d_v v + d_c tanh(v / v_s) + offset``; its
    velocity-dependent part (viscous + Coulomb) is the friction. Gravity the URDF misses (a
    payload, a balancer) stays in the offset and the residual, not in the share.

    Args:
        tau: (N, n) label torque [N*m].
        remainder: (N, n) label minus the nominal model [N*m].
        v: (N, n) joint velocities [rad/s].
        smoothing_velocity: v_s [rad/s].
    """
    n = tau.shape[1]
    friction = np.empty_like(remainder)
    for j in range(n):
        basis = np.column_stack([v[:, j], coulomb(v[:, j], smoothing_velocity), np.ones(len(v))])
        theta, *_ = np.linalg.lstsq(basis, remainder[:, j], rcond=None)
        friction[:, j] = basis[:, :2] @ theta[:2]
    label = rms(tau)
    return rms(friction) / np.where(label > 0, label, 1.0)


def high_friction_axes(share: np.ndarray, threshold: float = HIGH_FRICTION_SHARE) -> list[int]:
    """Axes whose friction share is at least ``threshold``; else the one with the largest share."""
    axes = [int(j) for j in np.flatnonzero(np.asarray(share) >= threshold)]
    return axes or [int(np.argmax(share))]


@dataclass(frozen=True)
class _Case:
    """The numbers of one label case that every rule reads."""

    joints: tuple[str, ...] | list[str]
    err: dict[str, np.ndarray]
    share: np.ndarray
    stopped_by: dict[str, str | None]
    axes: list[int]

    @property
    def names(self) -> str:
        """The high-friction axes' names."""
        return ', '.join(self.joints[j] for j in self.axes)

    @property
    def axes_text(self) -> str:
        """Which axes are high-friction, and why."""
        shares = ', '.join(
            f'{self.joints[j]} {self.share[j]:.0%}' for j in range(len(self.joints))
        )
        return (
            f'high-friction axes: {self.names} (friction share of the label RMS: {shares}; '
            f'threshold {HIGH_FRICTION_SHARE:.0%}, else the largest)'
        )


def _budget_notes(kinds: list[str], stopped_by: dict[str, str | None]) -> list[str]:
    notes = []
    for k in kinds:
        reason = stopped_by.get(k) or ''
        name = model_label(k)
        if reason.startswith('time_budget'):
            notes.append(f'{name} stopped at its time budget, so it may be under-trained')
        if reason.endswith('no validation gain after epoch 0'):
            notes.append(f'{name} never improved on the validation part: untrained')
    return notes


def _verdict(
    case: _Case,
    key: str,
    rule: str,
    kinds: tuple[str, ...],
    decide: Callable[[_Case], Decision],
) -> Finding:
    """Apply ``decide`` when the run has every kind it compares; else the finding is unchecked."""
    lacking = [model_label(k) for k in kinds if k not in case.err]
    if lacking:
        return Finding(
            key,
            STUDY_FINDINGS[key],
            rule,
            None,
            case.axes_text,
            f'not checked: the run lacks {", ".join(lacking)}',
        )
    holds, evidence, reasons = decide(case)
    notes = _budget_notes(list(kinds), case.stopped_by)
    return Finding(
        key,
        STUDY_FINDINGS[key],
        rule,
        holds,
        evidence,
        '' if holds else '; '.join(reasons + notes),
        '; '.join(notes) if holds else '',
    )


def _newtonian_wins(case: _Case) -> Decision:
    """``rnea_mlp_beats_lagrangian``: RNEA+MLP below DeLaN and LNN on every high-friction axis."""
    err, joints, axes, share = case.err, case.joints, case.axes, case.share
    newton, delan, lnn = err['rnea_mlp'], err['delan'], err['lnn']
    rows = [
        f'{joints[j]}: RNEA+MLP {newton[j]:.3g}, DeLaN {delan[j]:.3g}, LNN {lnn[j]:.3g}'
        for j in axes
    ]
    lost = [j for j in axes if not (newton[j] < delan[j] and newton[j] < lnn[j])]
    reasons = []
    if lost:
        reasons.append(
            f'on {", ".join(joints[j] for j in lost)} a Lagrangian network is at or below RNEA+MLP'
        )
        worse = [j for j in lost if 'mlp' in err and newton[j] > err['mlp'][j]]
        if worse:
            reasons.append(
                f'RNEA+MLP is also worse than the plain MLP on '
                f'{", ".join(joints[j] for j in worse)}: its network under-fits the '
                'remainder there'
            )
        if all(share[j] < HIGH_FRICTION_SHARE for j in axes):
            reasons.append(
                'no axis reaches the friction threshold, so the labels hold little '
                'dissipation to tell the model families apart'
            )
    return not lost, f'{case.axes_text}. ' + '; '.join(rows), reasons


def _gap_recovered(case: _Case) -> Decision:
    """``lnn_mlp_recovers_gap``: LNN+MLP closes enough of LNN's gap to RNEA+MLP."""
    err, axes = case.err, case.axes
    newton = float(np.mean(err['rnea_mlp'][axes]))
    lnn = float(np.mean(err['lnn'][axes]))
    hybrid = float(np.mean(err['lnn_mlp'][axes]))
    evidence = (
        f'mean normalised RMSE on {case.names}: LNN {lnn:.3g}, LNN+MLP {hybrid:.3g}, '
        f'RNEA+MLP {newton:.3g}'
    )
    gap = lnn - newton
    if gap <= 0:
        return (
            False,
            evidence,
            [
                'LNN is not worse than RNEA+MLP on these axes, so there is no gap to recover '
                '(see rnea_mlp_beats_lagrangian)'
            ],
        )
    recovered = (lnn - hybrid) / gap
    reasons = [f'LNN+MLP closes only {recovered:.0%} of the gap']
    if hybrid > lnn:
        reasons.append(
            'LNN+MLP is worse than LNN: its added network did not learn the friction within '
            'its training'
        )
    return (
        recovered >= GAP_RECOVERED_FRACTION,
        f'{evidence}; gap recovered {recovered:.0%}',
        reasons,
    )


def _lagrangian_competitive(case: _Case) -> Decision:
    """``lagrangian_competitive``: the better Lagrangian network close to RNEA+MLP on average."""
    err, joints, share = case.err, case.joints, case.share
    newton = float(np.mean(err['rnea_mlp']))
    best_kind = min(('delan', 'lnn'), key=lambda k: float(np.mean(err[k])))
    ratio = float(np.mean(err[best_kind])) / newton if newton > 0 else np.inf
    evidence = (
        f'mean normalised RMSE: RNEA+MLP {newton:.3g}, DeLaN '
        f'{float(np.mean(err["delan"])):.3g}, LNN {float(np.mean(err["lnn"])):.3g}; '
        f'{model_label(best_kind)} / RNEA+MLP = {ratio:.2f}. {case.axes_text}'
    )
    worst = int(np.argmax(err[best_kind] / np.maximum(err['rnea_mlp'], 1e-12)))
    reasons = [
        f'{model_label(best_kind)} is {ratio:.2f} x RNEA+MLP; its largest relative gap is on '
        f'{joints[worst]}'
    ]
    if share[worst] >= DISSIPATION_FREE_SHARE:
        reasons.append(
            f'the joint-torque label still holds dissipation on {joints[worst]} (friction '
            f'share {share[worst]:.0%}), which Lagrangian networks cannot represent'
        )
    elif bool(np.all(share < DISSIPATION_FREE_SHARE)):
        reasons.append(
            f'the label holds little dissipation (friction share below '
            f'{DISSIPATION_FREE_SHARE:.0%} on every axis), so the gap is not friction'
        )
    if 'mlp' in err and float(np.mean(err['mlp'])) > LAGRANGIAN_COMPETITIVE_RATIO * newton:
        reasons.append(
            f'the plain MLP is {float(np.mean(err["mlp"])) / newton:.2f} x RNEA+MLP too: '
            'RNEA+MLP starts from the URDF model, while the Lagrangian networks learn the '
            'whole dynamics from the data, which this training did not reach'
        )
    return bool(ratio <= LAGRANGIAN_COMPETITIVE_RATIO), evidence, reasons


def check_findings(
    target: str,
    joints: tuple[str, ...] | list[str],
    rmse_normalised: dict[str, np.ndarray],
    share: np.ndarray,
    stopped_by: dict[str, str | None] | None = None,
) -> list[Finding]:
    """Decide by explicit rules whether the study's findings hold for one label case.

    Rules (all on per-joint test RMSE on the normalised scale):

    * high-friction axes: friction share (``friction_share``) >= ``HIGH_FRICTION_SHARE``, or the
      axis with the largest share when none reaches it;
    * motor labels, ``rnea_mlp_beats_lagrangian``: on every high-friction axis RNEA+MLP is
      below both DeLaN and LNN;
    * motor labels, ``lnn_mlp_recovers_gap``: over the high-friction axes (mean), LNN+MLP closes
      at least ``GAP_RECOVERED_FRACTION`` of the gap between LNN and RNEA+MLP;
    * joint labels, ``lagrangian_competitive``: the better of DeLaN and LNN, averaged over all
      axes, is at most ``LAGRANGIAN_COMPETITIVE_RATIO`` times RNEA+MLP's.

    Args:
        target: 'motor' or 'joint'.
        joints: joint names.
        rmse_normalised: per kind, (n,) normalised RMSE.
        share: (n,) friction share of the label per joint.
        stopped_by: per kind, why its training stopped ('time_budget' flags under-training).
    """
    share = np.asarray(share, dtype=float)
    case = _Case(
        joints=joints,
        err={k: np.asarray(v, dtype=float) for k, v in rmse_normalised.items()},
        share=share,
        stopped_by=stopped_by or {},
        axes=high_friction_axes(share),
    )
    if target == 'motor':
        return [
            _verdict(
                case,
                'rnea_mlp_beats_lagrangian',
                'on every high-friction axis, RNEA+MLP has a lower normalised RMSE than DeLaN '
                'and than LNN',
                ('rnea_mlp', 'delan', 'lnn'),
                _newtonian_wins,
            ),
            _verdict(
                case,
                'lnn_mlp_recovers_gap',
                'mean over the high-friction axes: (LNN - LNN+MLP) / (LNN - RNEA+MLP) >= '
                f'{GAP_RECOVERED_FRACTION:.0%}',
                ('rnea_mlp', 'lnn', 'lnn_mlp'),
                _gap_recovered,
            ),
        ]
    return [
        _verdict(
            case,
            'lagrangian_competitive',
            'the better of DeLaN and LNN (normalised RMSE averaged over all axes) is at most '
            f'{LAGRANGIAN_COMPETITIVE_RATIO:g} x that of RNEA+MLP',
            ('rnea_mlp', 'delan', 'lnn'),
            _lagrangian_competitive,
        )
    ]
