"""The report's markdown sections: the accuracy, timing and study tables and the findings list.

Each function returns markdown lines (or one table) from plain numbers, so the text of
``report.md`` is written here and nowhere else; ``evaluation.report`` gathers the numbers and
puts the sections in order. The findings are decided in ``findings``, only written here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.evaluation.findings import (
    FRICTION_SMOOTHING_VELOCITY,
    HIGH_FRICTION_SHARE,
    Finding,
    model_label,
)
from id_learning.evaluation.study import STUDY_CITATION, StudyTable
from id_learning.twin.needed_torque import NEEDED_TORQUE_NOTES

__all__ = [
    'MODES',
    'accuracy_tables',
    'findings_section',
    'fmt',
    'markdown_table',
    'study_table',
    'timing_table',
]

#: How the models were fitted, by ``Dataset.mode``, as the report's first paragraph says it.
MODES = {
    'through_filter': (
        "through the label filter: each model's torque on a controller's inputs, low-passed "
        'like the labels before it met them'
    ),
    'study': "the study's way: low-passed inputs, torque against the low-passed labels as is",
}


def fmt(values: np.ndarray | list[float], digits: int = 3) -> str:
    """Numbers as a comma-separated list with ``digits`` significant digits."""
    return ', '.join(f'{x:.{digits}g}' for x in np.asarray(values, dtype=float))


def _ms(x: float | None, scale: float = 1e3, digits: int = 3) -> str:
    return '–' if x is None else f'{x * scale:.{digits}g}'


def markdown_table(head: list[str], rows: list[list[str]]) -> str:
    """A markdown table: the first column left-aligned, the others right-aligned."""
    lines = ['| ' + ' | '.join(head) + ' |', '|---|' + '---:|' * (len(head) - 1)]
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    return '\n'.join(lines)


def study_table(
    kinds: list[str],
    ours: dict[str, np.ndarray],
    joints: tuple[str, ...],
    table: StudyTable | None,
) -> str:
    """Our normalised RMSE (the study's way) beside the study's Table 1, or why it is absent."""
    if table is None:
        return (
            "**The study's Table 1 is not given**: it belongs to the paper and is not part of "
            'this package. Pass it as JSON with `train --study-table PATH` to place it beside '
            f'ours (see `id_learning/evaluation/study.py`). Study: {STUDY_CITATION}.'
        )
    head = ['model', *[f'{j} ours / study' for j in joints]]
    rows = []
    for kind in kinds:
        study = table.rmse_normalised.get(kind)
        cells = [
            f'{ours[kind][j]:.3g} / {study[j]:.3g}' if study else f'{ours[kind][j]:.3g} / –'
            for j in range(len(joints))
        ]
        rows.append([model_label(kind), *cells])
    missing = [k for k in table.rmse_normalised if k not in kinds]
    for kind in missing:
        study_only = [f'– / {x:.3g}' for x in table.rmse_normalised[kind]]
        rows.append([f'{model_label(kind)} (not trained here)', *study_only])
    notes = [
        f'Study: {table.source or STUDY_CITATION} (from `{table.path}`; its axes '
        f'{", ".join(table.joints)} are our {", ".join(joints)}).',
    ]
    if table.metric:
        notes.append(f'Its metric: {table.metric}.')
    if table.split_note:
        notes.append(f'Its split: {table.split_note}.')
    lines = [markdown_table(head, rows), '', ' '.join(notes)]
    if table.findings:
        lines += ['', "The study's findings, in its words:", '']
        lines += [f'- {finding}' for finding in table.findings]
    return '\n'.join(lines)


def _through_filter_tables(
    dataset: Dataset,
    metrics: dict[str, dict[str, Any]],
    kinds: list[str],
    floor: np.ndarray | None,
) -> list[str]:
    """Errors through the label filter [N*m], and against the noise-free torque where known."""
    joints = dataset.joints
    through = [[model_label(k), *(f'{x:.3g}' for x in metrics[k]['rmse_nm'])] for k in kinds]
    if floor is not None:
        through.append(['label-noise floor', *(f'{x:.3g}' for x in floor)])
    lines = [
        '## (a) Per-joint test RMSE through the label filter [N·m]',
        '',
        "Each model's torque along the whole recording, on the inputs a controller sends "
        f'({dataset.controller_inputs.describe()}), low-passed exactly like the labels '
        'and compared with them on the test part: the error a model can be judged by, whatever '
        'it was fitted on.'
        + (
            ' The floor is the RMS of the filtered label minus the filtered noise-free torque '
            '(twin ground truth): no model can go below it.'
            if floor is not None
            else _no_floor_because(dataset)
        ),
        '',
        markdown_table(['model', *joints], through),
        '',
    ]
    if floor is None or not all('rmse_true_nm' in metrics[k] for k in kinds):
        return lines
    ratio = [
        [model_label(k), *(f'{x:.2g}' for x in metrics[k]['rmse_through_filter_over_floor'])]
        for k in kinds
    ]
    truth = [
        [
            model_label(k),
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
    ]
    return [
        *lines,
        '### Through the filter, as a multiple of the label-noise floor',
        '',
        markdown_table(['model', *joints], ratio),
        '',
        '### Against the noise-free torque (twin ground truth) [N·m]',
        '',
        'Filtered: the filtered torque against the filtered noise-free torque (the error '
        'left once the label noise is taken out). Unfiltered: the torque against the '
        'noise-free torque sample by sample, what a drive would see; it includes what no '
        'label filtered at these cut-offs can teach (cogging, the sharpness of friction '
        'flips).',
        '',
        markdown_table(['model', *(f'{j} filtered / unfiltered' for j in joints)], truth),
        '',
        *_needed_torque_table(dataset, metrics, kinds),
    ]


def _needed_torque_table(
    dataset: Dataset, metrics: dict[str, dict[str, Any]], kinds: list[str]
) -> list[str]:
    """Errors against the torque the drive needs (twin), or one line saying why there are none."""
    heading = '### The torque the drive needs (twin: planned reference, no label delay) [N·m]'
    if not all('rmse_needed_nm' in metrics[k] for k in kinds):
        notes = dataset.extra.get(NEEDED_TORQUE_NOTES) or [
            'the metrics given lack it (scored before it existed); evaluate the run again'
        ]
        return [heading, '', 'Not computed: ' + '; '.join(notes) + '.', '']
    torque = 'tau_u' if dataset.target == 'motor' else 'joint torque'
    rows = [
        [
            model_label(k),
            *(
                f'{x:.3g} ({r:.2g}×)'
                for x, r in zip(
                    metrics[k]['rmse_needed_nm'], metrics[k]['rmse_needed_over_floor'], strict=True
                )
            ),
        ]
        for k in kinds
    ]
    return [
        heading,
        '',
        'Each model on the motion a controller plans and sends as its reference (exact '
        "positions in the encoder's coordinates, velocities and accelerations), against the "
        f'noise-free {torque} that motion needs at each sample time: the label without its '
        'delay (the currents lag the motion), with friction, cogging, offset and torque-constant '
        'scale as in the label. The feed-forward error a drive would see, free of the '
        'acceleration noise of inputs rebuilt from the recording; in brackets, as a multiple of '
        'the label-noise floor.',
        '',
        markdown_table(['model', *dataset.joints], rows),
        '',
    ]


def _no_floor_because(dataset: Dataset) -> str:
    """Why a twin's ground truth gave no floor here ('' for data without one, a real robot's)."""
    notes = dataset.extra.get('ground_truth_notes') or []
    if not notes:
        return ''
    return (
        ' No label-noise floor and no errors against the noise-free torque: '
        + '; '.join(notes)
        + '.'
    )


def _normalised_and_study_way_tables(
    joints: tuple[str, ...],
    metrics: dict[str, dict[str, Any]],
    kinds: list[str],
    target_scale: np.ndarray,
) -> list[str]:
    """Errors through the filter on the normalised scale, and the study's way [N*m]."""
    norm = [
        [
            model_label(k),
            *(f'{x:.3g}' for x in metrics[k]['rmse_normalised']),
            f'{np.mean(metrics[k]["rmse_normalised"]):.3g}',
        ]
        for k in kinds
    ]
    study = [
        [
            model_label(k),
            *(f'{x:.3g}' for x in metrics[k]['study_way']['rmse_nm']),
            f'{metrics[k]["study_way"]["mean_rmse_normalised"]:.3g}',
        ]
        for k in kinds
    ]
    return [
        '## (a) Through the filter, on the normalised [-1, 1] scale',
        '',
        'Each joint is divided by the half range of its training labels '
        f'({fmt(target_scale)} N·m).',
        '',
        markdown_table(['model', *joints, 'mean'], norm),
        '',
        "## (a) The study's way [N·m] (for comparison)",
        '',
        'Each model on inputs low-passed like the labels, its torque compared with the labels '
        "as is: the reference study's protocol. It grades an instantaneous model against a "
        'target that smears every friction flip over seconds, which no such model can match.',
        '',
        markdown_table(['model', *joints, 'mean normalised'], study),
        '',
    ]


def accuracy_tables(
    dataset: Dataset,
    metrics: dict[str, dict[str, Any]],
    kinds: list[str],
    noise_floor: np.ndarray | None,
    target_scale: np.ndarray,
) -> list[str]:
    """Section (a): errors through the filter, against the truth, and the study's way.

    Args:
        dataset: the evaluated data (joints, the controller's inputs).
        metrics: per kind, its metrics.json entry.
        kinds: the models, in report order.
        noise_floor: (n,) the label-noise floor [N*m], where known.
        target_scale: (n,) half ranges of the training labels [N*m].
    """
    return [
        *_through_filter_tables(dataset, metrics, kinds, noise_floor),
        *_normalised_and_study_way_tables(dataset.joints, metrics, kinds, target_scale),
    ]


def timing_table(
    metrics: dict[str, dict[str, Any]], kinds: list[str], stopped_by: dict[str, str | None]
) -> str:
    """Training time, epochs, why training stopped, and inference time per model."""
    return markdown_table(
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
                model_label(k),
                _ms(metrics[k].get('train_seconds'), 1.0),
                str((metrics[k].get('history') or {}).get('epochs', '–')),
                str(stopped_by[k] or '–'),
                _ms(metrics[k].get('inference_seconds_per_sample'), 1e6),
                _ms(metrics[k].get('latency_single_sample_median_s')),
                _ms(metrics[k].get('latency_single_sample_p99_s')),
            ]
            for k in kinds
        ],
    )


def _verdicts(findings: list[Finding]) -> list[str]:
    lines: list[str] = []
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
    return lines


def findings_section(
    findings: list[Finding], target: str, on_table: list[Finding] | None = None
) -> list[str]:
    """Section (e): the findings' verdicts on this run and on the study's own Table 1.

    How high-friction axes are found, then each finding's verdict and numbers; ``on_table``, if
    given, holds the same rules applied to the study's Table 1.
    """
    lines = [
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
    lines += _verdicts(findings)
    if on_table is not None:
        lines += [
            '',
            "The same rules on the study's own Table 1 (motor-current labels; its high-friction "
            "axes taken from this recording's friction share, the table having no data):",
            '',
            *_verdicts(on_table),
        ]
    other = 'joint' if target == 'motor' else 'motor'
    return [
        *lines,
        '',
        f'This run has {target} labels; the {other}-label finding is checked on a run with '
        f'`--target {other}` (see benchmarks/label_cases.py for both on the twin).',
        '',
    ]
