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
(e) per label case, whether the study's findings hold, by explicit rules (``check_findings``);

and what a controls engineer looks at beside them (``report_signals``):

(f) per model, its torque against the label per joint on the window of the test part where the
    motion is richest;
(g) per joint, the amplitude spectral density of each model's test error, with the label-noise
    floor drawn as white noise through the label filter;
(h) the closed loop on the twin (``closed_loop_report``), added by ``closed-loop`` when it is
    given this report.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.evaluation.data_summary import nominal_components
from id_learning.evaluation.findings import (
    DISSIPATION_FREE_SHARE,
    FRICTION_SMOOTHING_VELOCITY,
    GAP_RECOVERED_FRACTION,
    HIGH_FRICTION_SHARE,
    LAGRANGIAN_COMPETITIVE_RATIO,
    Finding,
    check_findings,
    friction_share,
    high_friction_axes,
    model_label,
)
from id_learning.evaluation.metrics import absolute_errors
from id_learning.evaluation.physics_report import identified_physics_section
from id_learning.evaluation.report_figures import (
    dissipative_figure,
    plot_boxes,
    plot_rmse,
    plot_shares,
    torque_splits,
)
from id_learning.evaluation.report_signals import (
    OVERLAY_SECONDS,
    LabelFloor,
    label_floor,
    plot_error_spectra,
    plot_torque_overlay,
    richest_window,
    stretches_of,
)
from id_learning.evaluation.report_tables import (
    MODES,
    accuracy_tables,
    findings_section,
    fmt,
    study_table,
    timing_table,
)
from id_learning.evaluation.scoring import predict_along, score_model
from id_learning.evaluation.study import StudyTable
from id_learning.models.base import InverseDynamicsModel
from id_learning.outputs import write_text_atomic
from id_learning.robot.config import RobotConfig
from id_learning.twin.needed_torque import needed_torque_of

__all__ = [
    'DISSIPATION_FREE_SHARE',
    'ERROR_SPECTRA_PNG',
    'FRICTION_SMOOTHING_VELOCITY',
    'GAP_RECOVERED_FRACTION',
    'HIGH_FRICTION_SHARE',
    'LAGRANGIAN_COMPETITIVE_RATIO',
    'OVERLAYS_DIR',
    'Finding',
    'ReportInput',
    'check_findings',
    'friction_share',
    'high_friction_axes',
    'write_report',
]

#: The folder of the torque overlays, one PNG per model kind (figure (f)).
OVERLAYS_DIR = 'torque_overlays'
#: The error spectra (figure (g)).
ERROR_SPECTRA_PNG = 'error_spectra.png'
#: The spectra of the errors against the torque the drive needs (figure (g'), twin data).
NEEDED_SPECTRA_PNG = 'needed_error_spectra.png'


class Figure(NamedTuple):
    """A figure of the report: its file (relative to report.md), heading and what it shows."""

    name: str
    caption: str
    sentence: str


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
        study_table: the study's Table 1 to place beside ours (``evaluation.study``), if given.
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
    study_table: StudyTable | None = None


def _predictions(report: ReportInput, kinds: list[str]) -> dict[str, np.ndarray]:
    """The given predictions through the label filter, scoring the models that lack them."""
    predictions = dict(report.predictions)
    for kind in kinds:
        if kind not in predictions:
            score = score_model(report.models[kind], report.dataset, report.target_scale)
            predictions[kind] = score.filtered
    return predictions


def _figures(
    report: ReportInput,
    predictions: dict[str, np.ndarray],
    rmse_norm: dict[str, np.ndarray],
    components: dict[str, np.ndarray],
    out: Path,
) -> list[Figure]:
    """Write the PNG figures (a)-(g) into ``out``; returns their files, captions and sentences."""
    ds = report.dataset
    joints, kinds = ds.joints, list(report.models)
    figures: list[Figure] = []
    floor = label_floor(ds, _evaluated_index(report), report.noise_floor)
    if kinds:
        target = ds.tau[_evaluated_index(report)]
        scaled = None if floor is None else floor.rms_nm / report.target_scale
        plot_rmse(
            joints, rmse_norm, out / 'rmse_per_joint.png', scaled, floor.label if floor else ''
        )
        figures.append(
            Figure(
                'rmse_per_joint.png',
                '(a) Test RMSE per joint, normalised scale',
                "Each model's test RMSE through the label filter, per joint"
                + (
                    f'; the dashed line is the {floor.label}: a bar on it has nothing left '
                    'to learn.'
                    if floor
                    else '.'
                ),
            )
        )
        plot_boxes(
            joints,
            {k: absolute_errors(predictions[k], target) for k in kinds},
            out / 'abs_error_boxplot.png',
        )
        figures.append(
            Figure(
                'abs_error_boxplot.png',
                '(b) Absolute test errors per joint and model',
                'How the errors spread: a long upper whisker is an error concentrated in few '
                'moments (a friction flip, a fast reversal), not a uniform offset.',
            )
        )
    if kinds and not ds.is_shuffled:  # a shuffled split's test samples form no stretch
        dissipative_figure(
            robot=report.robot,
            dataset=ds,
            rows=report.rows,
            models=report.models,
            predictions=predictions,
            path=out / 'dissipative_axis1.png',
        )
        figures.append(
            Figure(
                'dissipative_axis1.png',
                f'(c) Dissipative torque on {joints[0]}, test stretch',
                'What each model adds to the nominal rigid body against what the label holds '
                'beyond it: friction and what the URDF misses.',
            )
        )
    plot_shares(joints, torque_splits(ds, components, report.models), out / 'torque_shares.png')
    figures.append(
        Figure(
            'torque_shares.png',
            '(d) Share of the label torque per joint',
            'Which physical effect carries the label on each joint, so that an error can be '
            'weighed against the effect it belongs to.',
        )
    )
    if kinds and not ds.is_shuffled:
        figures += _signal_figures(report, predictions, floor, out)
    return figures


def _signal_figures(
    report: ReportInput,
    predictions: dict[str, np.ndarray],
    floor: LabelFloor | None,
    out: Path,
) -> list[Figure]:
    """Figures (f) and (g): torque overlays per model, and the error spectra per joint."""
    ds = report.dataset
    index = _evaluated_index(report)
    start, stop = richest_window(ds.controller, report.rows, round(OVERLAY_SECONDS / ds.period_s))
    # The window's place in the concatenated evaluated rows, where the predictions are.
    head = int(np.flatnonzero(index == start)[0])
    window = slice(head, head + stop - start)
    first = next(a for a, b in report.rows if a <= start < b)  # the evaluated range it is in
    t = (np.arange(start, stop) - first) * ds.period_s
    (out / OVERLAYS_DIR).mkdir(exist_ok=True)
    figures: list[Figure] = []
    for kind in report.models:
        name = f'{OVERLAYS_DIR}/{kind}.png'
        plot_torque_overlay(
            t=t,
            label=ds.tau[start:stop],
            prediction=predictions[kind][window],
            joints=ds.joints,
            kind=kind,
            target=ds.target,
            path=out / name,
        )
        figures.append(
            Figure(
                name,
                f'(f) {model_label(kind)}: predicted against measured torque',
                f'{model_label(kind)} (dashed, through the label filter) against the filtered '
                f'label (black) over {(stop - start) * ds.period_s:.0f} s from {t[0]:.0f} s '
                f'into the test part (rows {start}-{stop}), where the joints move and '
                'accelerate most.',
            )
        )
    target = ds.tau[index]
    plot_error_spectra(
        errors={k: predictions[k] - target for k in report.models},
        stretches=stretches_of(report.rows),
        dataset=ds,
        floor=floor,
        path=out / ERROR_SPECTRA_PNG,
    )
    figures.append(
        Figure(
            ERROR_SPECTRA_PNG,
            '(g) Spectra of the test errors per joint',
            'Where in frequency each error lies: below the dotted cut-off, what the model gets '
            'wrong in the motion; '
            + (
                f'the dashed line is the {floor.label} as white noise through the label filter: '
                'an error at the line is noise the labels carry.'
                if floor
                else 'no label-noise floor is known here.'
            ),
        )
    )
    return figures + _needed_spectra(report, out)


def _needed_spectra(report: ReportInput, out: Path) -> list[Figure]:
    """Figure (g'): the spectra of each feed-forward's error against the torque the drive needs.

    On a twin recording only (``twin.needed_torque``): each model as served to the drive
    (``for_the_drive``) on the planned reference, against the noise-free torque at each sample
    time, on the full band up to Nyquist, where the fast content a label filter hides shows.
    """
    ds = report.dataset
    needed = needed_torque_of(ds)
    if needed is None:
        return []
    index = _evaluated_index(report)
    runs = [np.arange(a, b) for a, b in report.rows]
    errors = {
        kind: predict_along(model.for_the_drive(), needed.reference, runs)[index]
        - needed.torque[index]
        for kind, model in report.models.items()
    }
    plot_error_spectra(
        errors=errors,
        stretches=stretches_of(report.rows),
        dataset=ds,
        floor=None,
        path=out / NEEDED_SPECTRA_PNG,
        full_band=True,
    )
    return [
        Figure(
            NEEDED_SPECTRA_PNG,
            "(g') Spectra of the feed-forward errors against the torque the drive needs",
            'Each model as the predictor serves it, on the reference a controller sends (the '
            "twin's planned motion), against the noise-free torque at each instant, up to "
            'Nyquist: what friction flips and cogging leave shows here, not through the label '
            'filter.',
        )
    ]


def _evaluated_index(report: ReportInput) -> np.ndarray:
    """The evaluated rows of the dataset, in order."""
    return np.concatenate([np.arange(a, b) for a, b in report.rows])


def _header(report: ReportInput) -> list[str]:
    """The title and what was evaluated: robot, labels, filter, data and fitting mode."""
    ds, robot = report.dataset, report.robot
    n = len(_evaluated_index(report))
    label = 'tau_u from motor currents' if ds.target == 'motor' else 'measured joint torque'
    return [
        f'# {report.title}',
        '',
        f'Robot {robot.name}, joints {", ".join(ds.joints)}. Labels: {label}, low-passed at '
        f'{fmt(ds.cutoff_hz)} Hz (zero-phase Butterworth, order {ds.filter_order}). Evaluated '
        f'on {report.evaluated_on} ({n} samples, {n * ds.period_s:.0f} s). '
        f'Models fitted {MODES[ds.mode]}.',
        '',
        *_data_warnings(ds),
    ]


def _data_warnings(dataset: Dataset) -> list[str]:
    """What loading the recordings warned of (a joint that never moves, a clipped label)."""
    warnings = dataset.extra.get('data_warnings') or []
    if not warnings:
        return []
    return ['**Data warnings** (the figures below hold with these):', '',
            *(f'- {text}' for text in warnings), '']  # fmt: skip


def _figures_section(figures: list[Figure]) -> list[str]:
    lines = ['## Figures', '']
    for name, caption, sentence in figures:
        lines += [f'### {caption}', '', sentence, '', f'![{caption}]({name})', '']
    return lines


def _study_table_findings(
    table: StudyTable | None, joints: tuple[str, ...], share: np.ndarray
) -> list[Finding] | None:
    """The motor-label findings decided on the study's own Table 1 (motor-current labels).

    Its high-friction axes are taken from this recording's friction share (same robot class):
    the table has no data to decide them from.
    """
    if table is None or len(table.joints) != len(joints):
        return None
    errors = {kind: np.asarray(row) for kind, row in table.rmse_normalised.items()}
    return check_findings('motor', joints, errors, share)


def write_report(report: ReportInput, out: Path) -> tuple[Path, list[dict[str, Any]]]:
    """Write ``report.md`` and its PNG figures into ``out``.

    Returns:
        The report's path and the checked findings (JSON-ready).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ds, metrics = report.dataset, report.metrics
    kinds = list(report.models)
    predictions = _predictions(report, kinds)
    rmse_norm = {k: np.asarray(metrics[k]['rmse_normalised']) for k in kinds}
    stopped_by = {k: _stopped_by(metrics[k].get('history') or {}) for k in kinds}

    components = nominal_components(ds, report.robot)
    share = friction_share(ds.tau, components['remainder'], ds.study.v)
    findings = check_findings(ds.target, ds.joints, rmse_norm, share, stopped_by)
    on_table = _study_table_findings(report.study_table, ds.joints, share)
    figures = _figures(report, predictions, rmse_norm, components, out)

    study_way = {k: np.asarray(metrics[k]['study_way']['rmse_normalised']) for k in kinds}
    lines = [
        *_header(report),
        *accuracy_tables(ds, metrics, kinds, report.noise_floor, report.target_scale),
        *identified_physics_section(report.models, report.robot),
        "### The study's Table 1",
        '',
        study_table(kinds, study_way, ds.joints, report.study_table),
        '',
        '## Training and inference time',
        '',
        timing_table(metrics, kinds, stopped_by),
        '',
        *findings_section(findings, ds.target, on_table),
        *_figures_section(figures),
    ]
    path = out / 'report.md'
    write_text_atomic(path, '\n'.join(lines))  # whole or absent, even on a full disk
    return path, [f.to_dict() for f in findings]


def _stopped_by(history: dict[str, Any]) -> str | None:
    """Why a network's fit stopped, and whether it ever improved on the validation part."""
    reason = history.get('stopped_by')
    if reason is not None and history.get('never_improved'):
        return f'{reason}; no validation gain after epoch 0'
    return reason
