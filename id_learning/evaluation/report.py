"""The study's exhibits on our data: report.md with tables, PNG figures and checked findings.

Exhibits (after Trinh et al. 2025, see evaluation/study.py):

(a) per-joint test RMSE of all models through the label filter (``evaluation.scoring``), in N*m
    next to the label-noise floor and on the normalised [-1, 1] scale; against the noise-free
    torque on twin recordings; the study's way as a labelled extra, with the study's Table 1
    beside it when bundled;
(b) box plots of absolute test errors per joint and model;
(c) the dissipative torque each model implies on a test stretch of axis 1: measured label minus
    the nominal RNEA, against each model's prediction minus the nominal RNEA (and its friction
    component, where the model separates one);
(d) the share of the label torque per joint from inertia, gravity, Coriolis, rotor inertia and
    friction (nominal split, and the RNEA+LQ split when that model was trained);
(e) per label case, whether the study's findings hold, by explicit rules (``check_findings``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.signals import lowpass
from id_learning.evaluation.data_summary import nominal_components, rms, shares
from id_learning.evaluation.metrics import absolute_errors
from id_learning.evaluation.physics_report import identified_physics_section
from id_learning.evaluation.scoring import score_model
from id_learning.evaluation.study import (
    MODEL_LABELS,
    STUDY_CITATION,
    STUDY_FINDINGS,
    STUDY_TABLE_1,
    STUDY_TABLE_1_CAPTION,
)
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.data import nominal_rnea
from id_learning.robot.config import RobotConfig

__all__ = [
    'DISSIPATION_FREE_SHARE',
    'FRICTION_SMOOTHING_VELOCITY',
    'GAP_RECOVERED_FRACTION',
    'HIGH_FRICTION_SHARE',
    'LAGRANGIAN_COMPETITIVE_RATIO',
    'Finding',
    'ReportInput',
    'check_findings',
    'friction_share',
    'high_friction_axes',
    'write_report',
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
#: Stretch of the test part shown in the dissipative-torque figure [s].
TRAJECTORY_SECONDS = 60.0

#: A rule's outcome: whether it holds, the numbers, and the reasons if it does not.
Decision = tuple[bool, str, list[str]]


@dataclass(frozen=True, eq=False)
class ReportInput:
    """Everything a report shows.

    Attributes:
        title: first heading.
        robot: the robot.
        dataset: the preprocessed data (all rows; shares use all of them).
        rows: the evaluated [start, stop) row ranges of ``dataset``, each contiguous in time.
        evaluated_on: a sentence saying which data ``rows`` are.
        target_scale: (n,) half ranges of the training labels [N*m].
        models: fitted models by kind, in report order.
        metrics: per kind, its metrics.json entry (rmse_nm, rmse_normalised, timings, history).
        predictions: per kind, (N_eval, n) predictions through the label filter on ``rows``
            [N*m] (``evaluation.scoring``); computed when absent.
        noise_floor: (n,) the label-noise floor on ``rows`` [N*m], where known.
    """

    title: str
    robot: RobotConfig
    dataset: Dataset
    rows: list[tuple[int, int]]
    evaluated_on: str
    target_scale: np.ndarray
    models: dict[str, InverseDynamicsModel]
    metrics: dict[str, dict[str, Any]]
    predictions: dict[str, np.ndarray] = field(default_factory=dict)
    noise_floor: np.ndarray | None = None


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


# -- analysis --------------------------------------------------------------------------------


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
        basis = np.column_stack([v[:, j], np.tanh(v[:, j] / smoothing_velocity), np.ones(len(v))])
        theta, *_ = np.linalg.lstsq(basis, remainder[:, j], rcond=None)
        friction[:, j] = basis[:, :2] @ theta[:2]
    label = rms(tau)
    return rms(friction) / np.where(label > 0, label, 1.0)


def high_friction_axes(share: np.ndarray, threshold: float = HIGH_FRICTION_SHARE) -> list[int]:
    """Axes whose friction share is at least ``threshold``; else the one with the largest share."""
    axes = [int(j) for j in np.flatnonzero(np.asarray(share) >= threshold)]
    return axes or [int(np.argmax(share))]


def _fmt(values: np.ndarray | list[float], digits: int = 3) -> str:
    return ', '.join(f'{x:.{digits}g}' for x in np.asarray(values, dtype=float))


def _label(kind: str) -> str:
    return MODEL_LABELS.get(kind, kind)


def _budget_notes(kinds: list[str], stopped_by: dict[str, str | None]) -> list[str]:
    return [
        f'{_label(k)} stopped at its time budget, so it may be under-trained'
        for k in kinds
        if stopped_by.get(k) == 'time_budget'
    ]


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
    stopped_by = stopped_by or {}
    share = np.asarray(share, dtype=float)
    err = {k: np.asarray(v, dtype=float) for k, v in rmse_normalised.items()}
    axes = high_friction_axes(share)
    names = ', '.join(joints[j] for j in axes)
    axes_text = (
        f'high-friction axes: {names} (friction share of the label RMS: '
        f'{", ".join(f"{joints[j]} {share[j]:.0%}" for j in range(len(joints)))}; threshold '
        f'{HIGH_FRICTION_SHARE:.0%}, else the largest)'
    )

    def verdict(
        key: str, rule: str, kinds: tuple[str, ...], decide: Callable[[], Decision]
    ) -> Finding:
        lacking = [_label(k) for k in kinds if k not in err]
        if lacking:
            return Finding(
                key,
                STUDY_FINDINGS[key],
                rule,
                None,
                axes_text,
                f'not checked: the run lacks {", ".join(lacking)}',
            )
        holds, evidence, reasons = decide()
        notes = _budget_notes(list(kinds), stopped_by)
        return Finding(
            key,
            STUDY_FINDINGS[key],
            rule,
            holds,
            evidence,
            '' if holds else '; '.join(reasons + notes),
            '; '.join(notes) if holds else '',
        )

    def newtonian_wins() -> Decision:
        newton, delan, lnn = err['rnea_mlp'], err['delan'], err['lnn']
        rows = [
            f'{joints[j]}: RNEA+MLP {newton[j]:.3g}, DeLaN {delan[j]:.3g}, LNN {lnn[j]:.3g}'
            for j in axes
        ]
        lost = [j for j in axes if not (newton[j] < delan[j] and newton[j] < lnn[j])]
        reasons = []
        if lost:
            reasons.append(
                f'on {", ".join(joints[j] for j in lost)} a Lagrangian network is at or below '
                'RNEA+MLP'
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
        return not lost, f'{axes_text}. ' + '; '.join(rows), reasons

    def gap_recovered() -> Decision:
        newton = float(np.mean(err['rnea_mlp'][axes]))
        lnn = float(np.mean(err['lnn'][axes]))
        hybrid = float(np.mean(err['lnn_mlp'][axes]))
        evidence = (
            f'mean normalised RMSE on {names}: LNN {lnn:.3g}, LNN+MLP {hybrid:.3g}, '
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

    def lagrangian_competitive() -> Decision:
        newton = float(np.mean(err['rnea_mlp']))
        best_kind = min(('delan', 'lnn'), key=lambda k: float(np.mean(err[k])))
        ratio = float(np.mean(err[best_kind])) / newton if newton > 0 else np.inf
        evidence = (
            f'mean normalised RMSE: RNEA+MLP {newton:.3g}, DeLaN '
            f'{float(np.mean(err["delan"])):.3g}, LNN {float(np.mean(err["lnn"])):.3g}; '
            f'{_label(best_kind)} / RNEA+MLP = {ratio:.2f}. {axes_text}'
        )
        worst = int(np.argmax(err[best_kind] / np.maximum(err['rnea_mlp'], 1e-12)))
        reasons = [
            f'{_label(best_kind)} is {ratio:.2f} x RNEA+MLP; its largest relative gap is on '
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

    if target == 'motor':
        return [
            verdict(
                'rnea_mlp_beats_lagrangian',
                'on every high-friction axis, RNEA+MLP has a lower normalised RMSE than DeLaN '
                'and than LNN',
                ('rnea_mlp', 'delan', 'lnn'),
                newtonian_wins,
            ),
            verdict(
                'lnn_mlp_recovers_gap',
                'mean over the high-friction axes: (LNN - LNN+MLP) / (LNN - RNEA+MLP) >= '
                f'{GAP_RECOVERED_FRACTION:.0%}',
                ('rnea_mlp', 'lnn', 'lnn_mlp'),
                gap_recovered,
            ),
        ]
    return [
        verdict(
            'lagrangian_competitive',
            'the better of DeLaN and LNN (normalised RMSE averaged over all axes) is at most '
            f'{LAGRANGIAN_COMPETITIVE_RATIO:g} x that of RNEA+MLP',
            ('rnea_mlp', 'delan', 'lnn'),
            lagrangian_competitive,
        )
    ]


# -- figures ---------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def _colours(kinds: list[str]) -> dict[str, Any]:
    order = list(MODEL_LABELS)
    plt = _pyplot()
    cmap = plt.get_cmap('tab10')
    return {k: cmap(order.index(k) if k in order else 7 + i % 3) for i, k in enumerate(kinds)}


def _plot_rmse(joints: tuple[str, ...], errors: dict[str, np.ndarray], path: Path) -> None:
    plt = _pyplot()
    kinds = list(errors)
    colours = _colours(kinds)
    fig, ax = plt.subplots(figsize=(11, 4.2), constrained_layout=True)
    width = 0.8 / max(len(kinds), 1)
    x = np.arange(len(joints))
    for i, kind in enumerate(kinds):
        ax.bar(
            x + (i - (len(kinds) - 1) / 2) * width,
            errors[kind],
            width,
            label=_label(kind),
            color=colours[kind],
        )
    ax.set_xticks(x, joints)
    values = np.concatenate([np.asarray(e, dtype=float) for e in errors.values()])
    positive = values[values > 0]
    if positive.size and positive.max() / positive.min() > 30:  # one bad model hides the rest
        ax.set_yscale('log')
    ax.set_ylabel('test RMSE, normalised [-1, 1] scale [-]')
    ax.set_title('Test RMSE per joint and model (lower is better)')
    ax.grid(axis='y', alpha=0.3)
    ax.legend(ncol=min(len(kinds), 7), fontsize=8, loc='upper left')
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_boxes(joints: tuple[str, ...], abs_errors: dict[str, np.ndarray], path: Path) -> None:
    plt = _pyplot()
    kinds = list(abs_errors)
    colours = _colours(kinds)
    n = len(joints)
    cols = 3 if n > 3 else n
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False, constrained_layout=True
    )
    for j in range(rows * cols):
        ax = axes.flat[j]
        if j >= n:
            ax.set_visible(False)
            continue
        data = [abs_errors[k][:, j] for k in kinds]
        boxes = ax.boxplot(
            data, showfliers=False, whis=(5, 95), patch_artist=True, medianprops={'color': 'k'}
        )
        for patch, kind in zip(boxes['boxes'], kinds, strict=True):
            patch.set_facecolor(colours[kind])
            patch.set_alpha(0.8)
        ax.set_xticks(
            range(1, len(kinds) + 1),
            [_label(k) for k in kinds],
            rotation=45,
            ha='right',
            fontsize=8,
        )
        ax.set_title(joints[j])
        ax.set_ylabel('|error| [N·m]')
        ax.grid(axis='y', alpha=0.3)
    fig.suptitle('Absolute test errors per joint and model (box: quartiles, whiskers: 5-95 %)')
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_dissipative(
    *,
    t: np.ndarray,
    measured: np.ndarray,
    estimates: dict[str, np.ndarray],
    frictions: dict[str, np.ndarray],
    joint: str,
    target: str,
    path: Path,
) -> None:
    plt = _pyplot()
    kinds = list(estimates)
    colours = _colours(kinds)
    cols = 2
    rows = int(np.ceil(len(kinds) / cols))
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(12, 2.3 * rows + 0.8),
        sharex=True,
        sharey=True,
        squeeze=False,
        constrained_layout=True,
    )
    label = 'tau_u' if target == 'motor' else 'tau'
    for i in range(rows * cols):
        ax = axes.flat[i]
        if i >= len(kinds):
            ax.set_visible(False)
            continue
        kind = kinds[i]
        ax.plot(t, measured, color='0.55', lw=1.4, label=f'measured {label} - RNEA')
        ax.plot(t, estimates[kind], color=colours[kind], lw=1.1, label=f'{_label(kind)} - RNEA')
        if kind in frictions:
            ax.plot(
                t,
                frictions[kind],
                color=colours[kind],
                lw=1.0,
                ls='--',
                label=f'{_label(kind)} friction part',
            )
        ax.set_title(_label(kind), fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc='upper right')
        if i % cols == 0:
            ax.set_ylabel('[N·m]')
    for ax in axes[-1]:
        ax.set_xlabel('time in the test part [s]')
    fig.suptitle(
        f'{joint}: torque beyond the nominal rigid body (RNEA, URDF parameters) on a test '
        'stretch: measured vs each model'
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_shares(
    joints: tuple[str, ...], splits: dict[str, dict[str, np.ndarray]], path: Path
) -> None:
    plt = _pyplot()
    fig, axes = plt.subplots(
        1, len(splits), figsize=(6.5 * len(splits), 5.0), squeeze=False, constrained_layout=True
    )
    palette = {
        'inertia': 'C0',
        'gravity': 'C1',
        'coriolis': 'C2',
        'rotor inertia': 'C4',
        'friction': 'C3',
        'remainder (friction and unmodelled)': 'C3',
        'unexplained': '0.7',
    }
    for ax, (title, split) in zip(axes[0], splits.items(), strict=True):
        bottom = np.zeros(len(joints))
        for name, values in split.items():
            ax.bar(joints, 100 * values, bottom=bottom, label=name, color=palette.get(name))
            bottom += 100 * values
        ax.set_ylabel('share of summed RMS torque [%]')
        ax.set_ylim(0, 100)
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=8, loc='upper center', bbox_to_anchor=(0.5, -0.09), ncol=3)
    fig.suptitle('Where the label torque comes from, per joint')
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- markdown --------------------------------------------------------------------------------


def _table(head: list[str], rows: list[list[str]]) -> str:
    lines = ['| ' + ' | '.join(head) + ' |', '|---|' + '---:|' * (len(head) - 1)]
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    return '\n'.join(lines)


def _study_table(kinds: list[str], ours: dict[str, np.ndarray], joints: tuple[str, ...]) -> str:
    if STUDY_TABLE_1 is None:
        return (
            "**The study's Table 1 is not bundled** with this package: its numbers could not be "
            'consulted when the report was written, and none are made up. To place them beside '
            'ours, copy them into `STUDY_TABLE_1` in `id_learning/evaluation/study.py`. '
            f'Study: {STUDY_CITATION}.'
        )
    head = ['model', *[f'{j} ours / study' for j in joints]]
    rows = []
    for kind in kinds:
        study = STUDY_TABLE_1.get(kind)
        cells = [
            f'{ours[kind][j]:.3g} / {study[j]:.3g}' if study else f'{ours[kind][j]:.3g} / –'
            for j in range(len(joints))
        ]
        rows.append([_label(kind), *cells])
    caption = f'Study: {STUDY_CITATION}. {STUDY_TABLE_1_CAPTION or ""}'
    return _table(head, rows) + '\n\n' + caption


_MODES = {
    'through_filter': (
        "through the label filter: each model's torque on a controller's inputs, low-passed "
        'like the labels before it met them'
    ),
    'study': "the study's way: low-passed inputs, torque against the low-passed labels as is",
}


def _accuracy_tables(report: ReportInput, kinds: list[str]) -> list[str]:
    """Section (a): errors through the filter, against the truth, and the study's way."""
    joints, metrics = report.dataset.joints, report.metrics
    floor = report.noise_floor

    def rows(key: str, digits: int = 3) -> list[list[str]]:
        return [[_label(k), *(f'{x:.{digits}g}' for x in metrics[k][key])] for k in kinds]

    through = rows('rmse_nm')
    if floor is not None:
        through.append(['label-noise floor', *(f'{x:.3g}' for x in floor)])
    lines = [
        '## (a) Per-joint test RMSE through the label filter [N·m]',
        '',
        "Each model's torque along the whole recording, on the inputs a controller sends "
        f'({report.dataset.controller_inputs.describe()}), low-passed exactly like the labels '
        'and compared with them on the test part: the error a model can be judged by, whatever '
        'it was fitted on.'
        + (
            ' The floor is the RMS of the filtered label minus the filtered noise-free torque '
            '(twin ground truth): no model can go below it.'
            if floor is not None
            else ''
        ),
        '',
        _table(['model', *joints], through),
        '',
    ]
    if floor is not None and all('rmse_true_nm' in metrics[k] for k in kinds):
        ratio = [
            [_label(k), *(f'{x:.2g}' for x in metrics[k]['rmse_through_filter_over_floor'])]
            for k in kinds
        ]
        lines += [
            '### Through the filter, as a multiple of the label-noise floor',
            '',
            _table(['model', *joints], ratio),
            '',
            '### Against the noise-free torque (twin ground truth) [N·m]',
            '',
            'Filtered: the filtered torque against the filtered noise-free torque (the error '
            'left once the label noise is taken out). Unfiltered: the torque against the '
            'noise-free torque sample by sample, what a drive would see; it includes what no '
            'label filtered at these cut-offs can teach (cogging, the sharpness of friction '
            'flips).',
            '',
            _table(
                ['model', *(f'{j} filtered / unfiltered' for j in joints)],
                [
                    [
                        _label(k),
                        *(
                            f'{f:.3g} / {u:.3g}'
                            for f, u in zip(
                                metrics[k]['rmse_true_through_filter_nm'],
                                metrics[k]['rmse_true_nm'],
                                strict=True,
                            )
                        ),
                    ]
                    for k in kinds
                ],
            ),
            '',
        ]
    norm = [
        [
            _label(k),
            *(f'{x:.3g}' for x in metrics[k]['rmse_normalised']),
            f'{np.mean(metrics[k]["rmse_normalised"]):.3g}',
        ]
        for k in kinds
    ]
    study = [
        [
            _label(k),
            *(f'{x:.3g}' for x in metrics[k]['study_way']['rmse_nm']),
            f'{metrics[k]["study_way"]["mean_rmse_normalised"]:.3g}',
        ]
        for k in kinds
    ]
    lines += [
        '## (a) Through the filter, on the normalised [-1, 1] scale',
        '',
        'Each joint is divided by the half range of its training labels '
        f'({_fmt(report.target_scale)} N·m).',
        '',
        _table(['model', *joints, 'mean'], norm),
        '',
        "## (a) The study's way [N·m] (for comparison)",
        '',
        'Each model on inputs low-passed like the labels, its torque compared with the labels '
        "as is: the reference study's protocol. It grades an instantaneous model against a "
        'target that smears every friction flip over seconds, which no such model can match.',
        '',
        _table(['model', *joints, 'mean normalised'], study),
        '',
    ]
    return lines


def _ms(x: float | None, scale: float = 1e3, digits: int = 3) -> str:
    return '–' if x is None else f'{x * scale:.{digits}g}'


def write_report(report: ReportInput, out: Path) -> tuple[Path, list[dict[str, Any]]]:
    """Write ``report.md`` and its PNG figures into ``out``.

    Returns:
        The report's path and the checked findings (JSON-ready).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ds, robot = report.dataset, report.robot
    joints = ds.joints
    kinds = list(report.models)
    index = np.concatenate([np.arange(a, b) for a, b in report.rows])
    target = ds.tau[index]
    predictions = dict(report.predictions)
    for kind in kinds:
        if kind not in predictions:
            score = score_model(report.models[kind], ds, report.target_scale)
            predictions[kind] = score.filtered
    rmse_norm = {k: np.asarray(report.metrics[k]['rmse_normalised']) for k in kinds}
    stopped_by = {k: (report.metrics[k].get('history') or {}).get('stopped_by') for k in kinds}

    components = nominal_components(ds, robot)
    share = friction_share(ds.tau, components['remainder'], ds.study.v)
    findings = check_findings(ds.target, joints, rmse_norm, share, stopped_by)

    figures: list[tuple[str, str]] = []
    if kinds:
        _plot_rmse(joints, rmse_norm, out / 'rmse_per_joint.png')
        figures.append(('rmse_per_joint.png', '(a) Test RMSE per joint, normalised scale'))
        _plot_boxes(
            joints,
            {k: absolute_errors(predictions[k], target) for k in kinds},
            out / 'abs_error_boxplot.png',
        )
        figures.append(('abs_error_boxplot.png', '(b) Absolute test errors per joint and model'))
        _dissipative_figure(report, predictions, out / 'dissipative_axis1.png')
        figures.append(
            ('dissipative_axis1.png', f'(c) Dissipative torque on {joints[0]}, test stretch')
        )
    nominal = shares(components)
    splits = {
        'nominal split (URDF rigid body + datasheet rotor inertia)': {
            'inertia': nominal['inertia'],
            'gravity': nominal['gravity'],
            'coriolis': nominal['coriolis'],
            'rotor inertia': nominal['rotor_inertia'],
            'remainder (friction and unmodelled)': nominal['remainder'],
        }
    }
    lq_split = _rnea_lq_split(report)
    if lq_split is not None:
        splits['RNEA+LQ split (fitted rotor inertia and friction)'] = lq_split
    _plot_shares(joints, splits, out / 'torque_shares.png')
    figures.append(('torque_shares.png', '(d) Share of the label torque per joint'))

    label = 'tau_u from motor currents' if ds.target == 'motor' else 'measured joint torque'
    lines = [
        f'# {report.title}',
        '',
        f'Robot {robot.name}, joints {", ".join(joints)}. Labels: {label}, low-passed at '
        f'{_fmt(ds.cutoff_hz)} Hz (zero-phase Butterworth, order {ds.filter_order}). Evaluated '
        f'on {report.evaluated_on} ({len(index)} samples, {len(index) * ds.period_s:.0f} s). '
        f'Models fitted {_MODES[ds.mode]}.',
        '',
        *_accuracy_tables(report, kinds),
        *identified_physics_section(report.models, robot),
        "### The study's Table 1",
        '',
        _study_table(
            kinds,
            {k: np.asarray(report.metrics[k]['study_way']['rmse_normalised']) for k in kinds},
            joints,
        ),
        '',
        '## Training and inference time',
        '',
        _table(
            [
                'model',
                'train [s]',
                'epochs',
                'stopped by',
                'batched [µs/sample]',
                'one sample, median [ms]',
                'one sample, p99 [ms]',
            ],
            [
                [
                    _label(k),
                    _ms(report.metrics[k].get('train_seconds'), 1.0),
                    str((report.metrics[k].get('history') or {}).get('epochs', '–')),
                    str(stopped_by[k] or '–'),
                    _ms(report.metrics[k].get('inference_seconds_per_sample'), 1e6),
                    _ms(report.metrics[k].get('latency_single_sample_median_s')),
                    _ms(report.metrics[k].get('latency_single_sample_p99_s')),
                ]
                for k in kinds
            ],
        ),
        '',
        "## (e) Do the study's findings hold on this data?",
        '',
        'High-friction axes are decided from the data, not from the models: per joint, viscous '
        'and Coulomb friction (d_v v + d_c tanh(v / '
        f'{FRICTION_SMOOTHING_VELOCITY:g} rad/s) + offset) is fitted by least squares to the '
        'nominal remainder (label minus URDF rigid body and datasheet rotor inertia); an axis '
        f'whose fitted friction carries at least {HIGH_FRICTION_SHARE:.0%} of the label RMS is '
        'high-friction. Gravity the URDF lacks (payload, balancer) does not count as friction.',
        '',
    ]
    for finding in findings:
        verdict = {True: 'holds', False: 'does NOT hold', None: 'not checked'}[finding.holds]
        lines += [
            f'- **{finding.key}: {verdict}.** Study: {finding.claim}',
            f'  - Rule: {finding.rule}.',
            f'  - Numbers: {finding.evidence}.',
        ]
        if finding.why:
            lines.append(f'  - Why: {finding.why}.')
        if finding.caveat:
            lines.append(f'  - Caveat: {finding.caveat}; longer training may change the verdict.')
    other = 'joint' if ds.target == 'motor' else 'motor'
    lines += [
        '',
        f'This run has {ds.target} labels; the {other}-label finding is checked on a run with '
        f'`--target {other}` (see benchmarks/label_cases.py for both on the twin).',
        '',
        '## Figures',
        '',
    ]
    for name, caption in figures:
        lines += [f'### {caption}', '', f'![{caption}]({name})', '']
    path = out / 'report.md'
    path.write_text('\n'.join(lines), encoding='utf-8')
    return path, [f.to_dict() for f in findings]


def _rnea_lq_split(report: ReportInput) -> dict[str, np.ndarray] | None:
    """The RNEA+LQ model's own split of the label, as shares; None without that model.

    Each part is the model's on a controller's inputs, filtered like the labels.
    """
    model = report.models.get('rnea_lq')
    if model is None:
        return None
    ds = report.dataset
    motion = ds.controller
    parts = model.components(motion.q, motion.v, motion.a)
    named = {
        'inertia': parts.inertial,
        'gravity': parts.gravity,
        'coriolis': parts.coriolis,
        'rotor inertia': parts.rotor_inertia,
        'friction': parts.friction,
    }
    present = {k: ds.filter_like_labels(v) for k, v in named.items() if v is not None}
    if not present:
        return None
    present['unexplained'] = ds.tau - ds.filter_like_labels(parts.total)
    return shares(present)


def _dissipative_figure(
    report: ReportInput, predictions: dict[str, np.ndarray], path: Path
) -> None:
    """Plot axis 1 on the first evaluated stretch (at most TRAJECTORY_SECONDS), filtered.

    The stretch starts at ``rows[0]``, where the evaluated predictions begin: their head is
    reused. Everything is shown as the labels see it: through the label filter.
    """
    ds = report.dataset
    a, b = report.rows[0]
    b = min(b, a + round(TRAJECTORY_SECONDS / ds.period_s))
    motion = ds.controller
    rigid_body = nominal_rnea(report.robot, motion.q, motion.v, motion.a)
    baseline = ds.filter_like_labels(rigid_body)[a:b, 0]
    measured = ds.tau[a:b, 0] - baseline
    estimates, frictions = {}, {}
    stretch = motion.take(slice(a, b))
    for kind, model in report.models.items():
        estimates[kind] = predictions[kind][: b - a, 0] - baseline
        if not model.is_sequence_model:
            friction = model.components(stretch.q, stretch.v, stretch.a).friction
            if friction is not None:
                frictions[kind] = lowpass(friction, ds.cutoff_hz, ds.period_s, ds.filter_order)[
                    :, 0
                ]
    t = np.arange(b - a) * ds.period_s
    _plot_dissipative(
        t=t,
        measured=measured,
        estimates=estimates,
        frictions=frictions,
        joint=ds.joints[0],
        target=ds.target,
        path=path,
    )
