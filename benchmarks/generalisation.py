"""Unseen motion of the same twin robot: every kind's error and its feed-forward in the loop.

    python benchmarks/generalisation.py [--max-seconds-per-model 150] [--unseen-seed 2031]
        [--unseen-duration 300] [--closed-loop-seconds 60] [--work DIR [--reuse]]

The acceptance figures of the identified kinds (``rnea_id``, ``rnea_id_mlp``, ``delan_id``,
``lnn_mlp_id``) beside the study's seven, all through the ``id-learning`` CLI, each step a
subprocess whose wall time is recorded:

1. ``simulate``: a recording of unseen motion of the shipped bag's robot,
   ``--config config/twin_default.yaml --seed 2031 --robot-seed 2026`` (the excitation and the
   sensor noise are new, the hidden robot is the one behind ``bags/default``; the two bags'
   ground_truth.json are compared to say so), ``--unseen-duration`` seconds long;
2. ``train`` on ``bags/default`` (600 s, seed 2026) every kind of ``--models``, each network
   within ``--max-seconds-per-model``; the study's Table 1 is passed on (``--study-table``)
   when ``--study-table`` names a file, so that the run's own report places it;
3. ``evaluate`` the run on the whole unseen recording: per kind and joint the RMSE through the
   label filter over the label-noise floor, the RMSE against the torque the drive needs on the
   planned reference over the same floor, and the normalised RMSE (the training labels' scale);
4. ``closed-loop --bag`` on the twin: the unseen recording tracked from its start on its own
   twin; per kind its tracking RMS over the true inverse dynamics', and its improvement
   (feedback alone's RMS over its own) against ``rnea_id``'s.

Then the acceptance checks, each pass or fail with its figure: ``rnea_id_mlp`` within 1.5 x
the floor on every joint through the filter, ``delan_id`` and ``lnn_mlp_id`` within 3 x; each
identified network at least 10 x better than its study-faithful variant in mean normalised
RMSE; their closed-loop improvement at least 0.8 x ``rnea_id``'s on every joint; ``rnea_id``
within 1.25 x the true inverse dynamics in the loop on every joint and its error against the
needed torque within 2 x the floor on every joint.

The work folder (``--work``; default a temporary folder, removed after a complete run, kept with
its path printed when a step failed) holds the bag, the run, the evaluation and the closed loop
with their logs; ``--reuse`` keeps what a complete earlier step left there. Prints the page on
stderr and the JSON document on stdout; writes docs/results/generalisation.json and .md (not with
``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import (
    DEFAULT_BAG,
    DEFAULT_ROBOT,
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    repo_path,
    settings_lines,
    verdict,
)

NAME = 'generalisation'
STUDY_KINDS = ('rnea_lq', 'rnea_mlp', 'delan', 'lnn', 'lnn_mlp', 'mlp', 'lstm')
IDENTIFIED_KINDS = ('rnea_id', 'rnea_id_mlp', 'delan_id', 'lnn_mlp_id')
#: Each identified network and the study-faithful kind it is compared with.
VARIANTS = {'rnea_id_mlp': 'rnea_mlp', 'delan_id': 'delan', 'lnn_mlp_id': 'lnn_mlp'}
DEFAULT_TWIN = REPO / 'config' / 'twin_default.yaml'
DEFAULT_STUDY_TABLE = REPO.parent / 'shared' / 'data' / 'study_table1' / 'table1.json'
#: The names closed-loop gives the two reference runs (evaluation.closed_loop).
FEEDBACK_ONLY = 'feedback only'
TRUE_DYNAMICS = 'true inverse dynamics'
#: Acceptance thresholds.
FLOOR_LIMITS = {'rnea_id_mlp': 1.5, 'delan_id': 3.0, 'lnn_mlp_id': 3.0}
VARIANT_FACTOR = 10.0
LOOP_SHARE = 0.8
LOOP_TO_TRUE = 1.25
NEEDED_LIMIT = 2.0


# -- the steps ----------------------------------------------------------------------------------
def cli(*args: str | Path | float) -> list[str]:
    """The command line of one ``id-learning`` subcommand in this interpreter."""
    return [sys.executable, '-m', 'id_learning.cli', *map(str, args)]


def run_step(name: str, command: list[str], log: Path, done: Path | None = None) -> dict[str, Any]:
    """Run one subprocess (stdout and stderr into ``log``); its wall time and outcome.

    With ``done`` given and present (``--reuse``), nothing runs and the step says so.
    """
    if done is not None and done.exists():
        print(f'{name}: reusing {done}', file=sys.stderr, flush=True)
        return {'reused': str(done), 'returncode': 0, 'wall_s': None}
    print(f'{name}: {" ".join(command[3:])}', file=sys.stderr, flush=True)
    start = time.perf_counter()
    with log.open('w', encoding='utf-8') as out:
        result = subprocess.run(
            command, cwd=REPO, stdout=out, stderr=subprocess.STDOUT, text=True, check=False
        ).returncode
    step: dict[str, Any] = {
        'wall_s': round(time.perf_counter() - start, 1),
        'returncode': result,
        'log': str(log),
    }
    if result != 0:
        lines = log.read_text(encoding='utf-8', errors='replace').strip().splitlines()
        step['error'] = '\n'.join(lines[-12:])
        print(f'{name} exited {result}:\n{step["error"]}', file=sys.stderr)
    print(f'{name}: {step["wall_s"]:.0f} s wall', file=sys.stderr, flush=True)
    return step


def read_json(path: Path) -> dict[str, Any] | None:
    """A JSON file's content, or None where it is absent."""
    return json.loads(path.read_text(encoding='utf-8')) if path.is_file() else None


def same_robot(bag: Path, other: Path) -> bool | None:
    """Whether two twin bags hide the same robot (ground_truth.json's ``true``), None: unknown."""
    truths = [read_json(b / 'ground_truth.json') for b in (bag, other)]
    if any(t is None or 'true' not in t for t in truths):
        return None
    return bool(truths[0]['true'] == truths[1]['true'])  # type: ignore[index]


# -- the figures --------------------------------------------------------------------------------
def as_float(value: Any) -> float:
    """A figure as a float; None (a diverged loop, a missing joint) as infinity."""
    return math.inf if value is None else float(value)


def json_number(value: float) -> float | None:
    """A float for JSON, which has no infinity or NaN: those become None."""
    return value if math.isfinite(value) else None


def model_figures(evaluation: dict[str, Any], run_metrics: dict[str, Any] | None) -> dict:
    """Per kind, from evaluate's metrics.json (and the run's): the figures on the page."""
    test_part = (run_metrics or {}).get('models', {})
    out = {}
    for kind, m in evaluation['models'].items():
        out[kind] = {
            'through_filter_over_floor': m.get('rmse_through_filter_over_floor'),
            'needed_over_floor': m.get('rmse_needed_over_floor'),
            'normalised': m.get('rmse_through_filter_normalised'),
            'mean_normalised': m.get('mean_rmse_through_filter_normalised'),
            'test_part_mean_normalised': test_part.get(kind, {}).get(
                'mean_rmse_through_filter_normalised'
            ),
            'test_part_over_floor': test_part.get(kind, {}).get('rmse_through_filter_over_floor'),
            'train_seconds': test_part.get(kind, {}).get('train_seconds'),
            'history': test_part.get(kind, {}).get('history'),
        }
    return out


def distance_to_rnea_id(models: dict[str, Any]) -> dict[str, dict[str, float | None]]:
    """Per identified network: the largest relative difference of its (a) and (b) from rnea_id's.

    Near zero, the network on top of the identified physics changed nothing measurable, and the
    checks on it judge rnea_id's figures.
    """
    base = models.get('rnea_id')
    out: dict[str, dict[str, float | None]] = {}
    for kind in VARIANTS:
        if base is None or kind not in models:
            continue
        out[kind] = {}
        for key in ('through_filter_over_floor', 'needed_over_floor'):
            mine, theirs = models[kind][key], base[key]
            out[kind][key] = (
                None
                if mine is None or theirs is None
                else max(abs(m / t - 1.0) for m, t in zip(mine, theirs, strict=True))
            )
    return out


def loop_figures(closed_loop: dict[str, Any]) -> dict[str, Any]:
    """Per run of closed_loop.json: RMS [rad], over the true inverse dynamics', improvement."""
    runs = closed_loop['runs']
    n = len(closed_loop['joints'])
    # A diverged loop has no RMS (None): infinite.
    rms = {name: [as_float(x) for x in (r['rms_rad'] or [None] * n)] for name, r in runs.items()}
    base, true = rms[FEEDBACK_ONLY], rms[TRUE_DYNAMICS]
    reference = rms.get('rnea_id')
    out = {}
    for name, values in rms.items():
        improvement = [b / v for b, v in zip(base, values, strict=True)]
        entry = {
            'rms_rad': [json_number(v) for v in values],
            'over_true': [json_number(v / t) for v, t in zip(values, true, strict=True)],
            'improvement': [json_number(x) for x in improvement],
            'diverged_at_cycle': runs[name].get('diverged_at_cycle'),
            'saturated_cycles': runs[name].get('saturated_cycles'),
        }
        if reference is not None:
            # improvement / rnea_id's improvement = rnea_id's RMS / this run's RMS
            entry['improvement_over_rnea_id'] = [
                json_number(r / v) for r, v in zip(reference, values, strict=True)
            ]
        out[name] = entry
    return out


def extreme(values: list[float | None] | None, joints: list[str], largest: bool = True) -> tuple:
    """(value, joint) of the largest (or smallest) figure over joints; None (infinite) counts.

    (None, None) where there are no figures.
    """
    if not values:
        return None, None
    pairs = [(as_float(v), joint) for v, joint in zip(values, joints, strict=True)]
    return max(pairs) if largest else min(pairs)


def acceptance(document: dict[str, Any]) -> list[dict[str, Any]]:
    """The acceptance checks: what each asks, its figure, pass or fail (missing figures fail)."""
    joints, models = document['joints'], document['models']
    loop = document.get('closed_loop', {}).get('figures', {})
    checks: list[dict[str, Any]] = []

    def judge(check: str, kind: str, values: Any, limit: float, at_most: bool) -> None:
        """One check over joints: the worst joint's figure against ``limit``."""
        value, joint = extreme(values, joints, largest=at_most)
        if value is None:
            why = document['failed_models'].get(kind)
            figure = f'no figure for {kind}' + (f' (failed: {why})' if why else '')
            passed = False
        else:
            figure = f'{"worst" if at_most else "least"} {number(value)} x ({joint})'
            passed = value <= limit if at_most else value >= limit
        checks.append({'check': check, 'figure': figure, 'passed': passed})

    for kind, limit in FLOOR_LIMITS.items():
        judge(
            f'{kind} through the filter within {limit:g} x floor on every joint (unseen motion)',
            kind,
            models.get(kind, {}).get('through_filter_over_floor'),
            limit,
            at_most=True,
        )
    for kind, study_kind in VARIANTS.items():
        check = (
            f'{kind} at least {VARIANT_FACTOR:g} x better than {study_kind} in mean normalised '
            'RMSE (unseen motion)'
        )
        mine, theirs = models.get(kind, {}), models.get(study_kind, {})
        if mine.get('mean_normalised') is None or theirs.get('mean_normalised') is None:
            judge(
                check,
                kind if mine.get('mean_normalised') is None else study_kind,
                None,
                VARIANT_FACTOR,
                at_most=False,
            )
            continue
        factor = theirs['mean_normalised'] / mine['mean_normalised']
        per_joint = [t / m for t, m in zip(theirs['normalised'], mine['normalised'], strict=True)]
        least, joint = extreme(per_joint, joints, largest=False)
        ratio = f'{number(theirs["mean_normalised"])} / {number(mine["mean_normalised"])}'
        figure = f'{ratio} = {number(factor)} x (per joint at least {number(least)} x, {joint})'
        checks.append({'check': check, 'figure': figure, 'passed': factor >= VARIANT_FACTOR})
    for kind in VARIANTS:
        judge(
            f"{kind}'s closed-loop improvement at least {LOOP_SHARE:g} x rnea_id's on every joint",
            kind,
            loop.get(kind, {}).get('improvement_over_rnea_id'),
            LOOP_SHARE,
            at_most=False,
        )
    judge(
        f'rnea_id within {LOOP_TO_TRUE:g} x the true inverse dynamics in the loop on every joint '
        '(tracking RMS)',
        'rnea_id',
        loop.get('rnea_id', {}).get('over_true'),
        LOOP_TO_TRUE,
        at_most=True,
    )
    judge(
        f'rnea_id against the needed torque within {NEEDED_LIMIT:g} x floor on every joint '
        '(unseen motion)',
        'rnea_id',
        models.get('rnea_id', {}).get('needed_over_floor'),
        NEEDED_LIMIT,
        at_most=True,
    )
    return checks


# -- the page -----------------------------------------------------------------------------------
def per_joint_table(
    rows: dict[str, list[float | None] | None], joints: list[str], summary: str = 'max'
) -> list[str]:
    """Rows of per-joint figures with their max (or mean) over joints."""
    reduce = max if summary == 'max' else (lambda xs: sum(xs) / len(xs))
    body = []
    for name, values in rows.items():
        if values is None:
            body.append([name, *(['-'] * (len(joints) + 1))])
            continue
        body.append(
            [
                name,
                *(number(v) for v in values),
                number(reduce([as_float(v) for v in values])),
            ]
        )
    return markdown_table(['', *joints, summary], body)


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The page's body: what ran, the four tables, the acceptance checks, the study's table."""
    joints, models, kinds = document['joints'], document['models'], document['kinds']
    loop = document.get('closed_loop', {})
    figures = loop.get('figures', {})
    steps = document['steps']
    unseen = document['unseen']
    robot_text = {
        True: 'the same hidden robot (their ground_truth.json agree)',
        False: 'NOT the same hidden robot (their ground_truth.json differ)',
        None: 'a robot not compared with it (no ground_truth.json)',
    }[unseen['same_robot']]
    lines = [
        f'Every kind trained on `{repo_path(document["train_bag"])}` and scored on motion it '
        f'has not seen: a {unseen["duration_s"]:g} s recording of the twin '
        f'`{repo_path(document["twin_config"])}` with seed {unseen["seed"]} and robot seed '
        f'{unseen["robot_seed"]}, {robot_text}. Each fit had '
        f'{document["max_seconds_per_model"]:g} s (`--max-seconds-per-model`). '
        + wall_text(document),
        '',
        *settings,
    ]
    lines += markdown_table(
        ['step', 'wall [s]', 'note'],
        [[name, number(s.get('wall_s'), '.0f'), step_note(s)] for name, s in steps.items()],
        align='lrl',
    )
    lines.append('')
    lines += [
        'Training (`train`: early stopping on the last 15 % of the training part, within the '
        'budget):',
        '',
        *training_table(document),
        '',
    ]
    for kind, why in document['failed_models'].items():
        lines.append(f'- `{kind}` failed: {why}')
    if document['failed_models']:
        lines.append('')

    floor = document.get('label_noise_floor_nm')
    lines += [
        '## (a) Through the label filter on unseen motion, x label-noise floor',
        '',
        "Each model's torque on a controller's inputs along the whole unseen recording, "
        'low-passed like the labels, against the labels; RMSE over the floor (the filtered label '
        'minus the filtered noise-free torque). 1 is as good as the labels allow. Floor [N*m]: '
        + (
            ', '.join(f'{j} {number(x)}' for j, x in zip(joints, floor, strict=True))
            if floor
            else 'absent'
        )
        + '.',
        '',
        *per_joint_table(
            {k: models[k]['through_filter_over_floor'] for k in kinds if k in models}, joints
        ),
        '',
        '## (b) Against the torque the drive needs, x label-noise floor',
        '',
        'Each model on the planned reference of the unseen recording against the noise-free '
        "torque the drive needs at each sample time (without the labels' delay, unfiltered), "
        'over the same floor.',
        '',
        *per_joint_table(
            {k: models[k]['needed_over_floor'] for k in kinds if k in models}, joints
        ),
        '',
    ]
    if loop:
        reference = loop['reference']
        lines += [
            "## (c) Closed loop: tracking RMS / the true inverse dynamics'",
            '',
            f'`id-learning closed-loop --bag` tracks {reference["duration_s"]:g} s of '
            f'{reference["part"]}, the unseen recording of (a) and (b), on its twin (rows '
            f'{reference["rows"][0]} to {reference["rows"][1]}). Position P / velocity PI at the '
            "IPO period, each model's tau_u as feed-forward; 1 is as good as the true inverse "
            'dynamics.',
            '',
            *per_joint_table(
                {
                    name: figures[name]['over_true']
                    for name in [FEEDBACK_ONLY, *kinds]
                    if name in figures
                },
                joints,
            ),
            '',
            "## (d) Closed-loop improvement relative to rnea_id's",
            '',
            "Improvement: feedback alone's tracking RMS over the model's, per joint; here "
            "divided by rnea_id's (first row: rnea_id's own improvement). Above 1 tracks better "
            'than rnea_id.',
            '',
            *per_joint_table(
                {
                    'rnea_id improvement': figures.get('rnea_id', {}).get('improvement'),
                    **{
                        k: figures[k].get('improvement_over_rnea_id')
                        for k in kinds
                        if k in figures
                    },
                },
                joints,
                summary='mean',
            ),
            '',
        ]
        diverged = [n for n, f in figures.items() if f['diverged_at_cycle'] is not None]
        if diverged:
            lines += [f'Diverged in the loop: {", ".join(diverged)} (their figures: -).', '']
    else:
        lines += ['## (c), (d) Closed loop', '', 'Not run: ' + loop_missing(document), '']

    lines += ['## Acceptance', '']
    lines += [
        f'- **{verdict(c["passed"]).upper()}**: {c["check"]}: {c["figure"]}'
        for c in document['checks']
    ]
    passed = sum(bool(c['passed']) for c in document['checks'])
    lines += ['', f'{passed} of {len(document["checks"])} checks pass.', '']
    distance = document.get('distance_to_rnea_id') or {}
    if distance:
        lines += [
            "How far each network on the identified physics is from rnea_id's own figures "
            '(largest relative difference over the joints; near 0: the network changed nothing '
            "measurable, and the checks on it judge rnea_id's figures): "
            + '; '.join(
                f'{kind} {number(d["through_filter_over_floor"], ".2g")} in (a), '
                f'{number(d["needed_over_floor"], ".2g")} in (b)'
                for kind, d in distance.items()
            )
            + '.',
            '',
        ]

    lines += [
        '## Normalised RMSE beside the study',
        '',
        'Test RMSE per joint on the normalised [-1, 1] scale of the training labels, through the '
        "filter, on the unseen recording; the last column is the mean on the run's own test "
        'part (the last 30 % of the training recording).',
        '',
        *markdown_table(
            ['', *joints, 'mean', 'mean, test part'],
            [
                [
                    kind,
                    *(number(x) for x in (models[kind]['normalised'] or [])),
                    number(models[kind]['mean_normalised']),
                    number(models[kind]['test_part_mean_normalised']),
                ]
                for kind in kinds
                if kind in models
            ],
        ),
        '',
        study_lines(document['study_table']),
    ]
    return lines


def loop_missing(document: dict[str, Any]) -> str:
    """Why the closed loop has no figures."""
    step = document['steps'].get('closed-loop')
    if step is None:
        return 'no run to track with.'
    return step.get('error') or 'closed_loop.json absent.'


def study_lines(study: dict[str, Any]) -> str:
    """Where the study's Table 1 is, or that it is absent (its figures are never copied)."""
    if not study['present']:
        return f"The study's Table 1 (`{study['path']}`) is absent here: nothing to place beside."
    licence = (
        f'its folder has a {study["license"]}'
        if study.get('license')
        else 'its folder carries no license'
    )
    return (
        f"The study's Table 1, the same metric on the study's own robot and data: "
        f'`{study["path"]}` ({study["rows"]} models). Its figures belong to the paper and are '
        f"not copied onto this page ({licence}); the run's own report.md places them beside "
        'its test-part figures (`train --study-table`).'
    )


def training_table(document: dict[str, Any]) -> list[str]:
    """Per kind: fit time, epochs, best epoch, what stopped it, whether validation improved."""
    rows = []
    for kind in document['kinds']:
        figures = document['models'][kind]
        history = figures.get('history') or {}
        cut = '; '.join(document['cut_short'].get(kind, []))
        improved = history.get('never_improved')
        rows.append(
            [
                kind,
                number(figures.get('train_seconds'), '.0f'),
                number(history.get('epochs')),
                number(history.get('best_epoch')),
                history.get('stopped_by') or cut or '-',
                '-' if improved is None else ('no' if improved else 'yes'),
            ]
        )
    header = ['kind', 'fit [s]', 'epochs', 'best epoch', 'stopped by', 'validation improved']
    return markdown_table(header, rows, align='lrrrll')


def wall_text(document: dict[str, Any]) -> str:
    """How long the whole run took, or that steps were reused (their time not measured)."""
    if any(step.get('reused') for step in document['steps'].values()):
        return 'Steps reused from `--work` were not timed in this run.'
    return f'The whole run took {document["wall_s"] / 60:.1f} min of wall time.'


def step_note(step: dict[str, Any]) -> str:
    """A step's note in the table: reused, or its exit status where it failed."""
    if step.get('reused'):
        return 'reused from --work'
    return f'exit {step["returncode"]}' if step.get('returncode') else ''


# -- main ---------------------------------------------------------------------------------------
def study_table(path: Path) -> dict[str, Any]:
    """Whether the study's Table 1 is there, and how many models it holds."""
    if not path.is_file():
        return {'path': repo_path(path), 'present': False}
    from id_learning.evaluation.study import load_study_table

    table = load_study_table(path)
    licence = next((p.name for p in sorted(path.parent.glob('LICEN[CS]E*'))), None)
    return {
        'path': repo_path(path),
        'present': True,
        'rows': len(table.rmse_normalised),
        'license': licence,
    }


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bag', type=Path, default=DEFAULT_BAG, help='the training recording')
    parser.add_argument('--robot', type=Path, default=DEFAULT_ROBOT)
    parser.add_argument(
        '--twin', type=Path, default=DEFAULT_TWIN, help='twin config of the unseen recording'
    )
    parser.add_argument('--unseen-seed', type=int, default=2031, help='its excitation and noise')
    parser.add_argument(
        '--robot-seed', type=int, default=2026, help="its hidden robot (the training bag's)"
    )
    parser.add_argument('--unseen-duration', type=float, default=300.0, help='its length [s]')
    parser.add_argument(
        '--models',
        default=','.join((*STUDY_KINDS, *IDENTIFIED_KINDS)),
        help='comma-separated kinds to train (default: the study seven and the identified four)',
    )
    parser.add_argument(
        '--max-seconds-per-model', type=float, default=150.0, help='each fit [s] (train)'
    )
    parser.add_argument(
        '--closed-loop-seconds', type=float, default=60.0, help='unseen motion tracked [s]'
    )
    parser.add_argument('--study-table', type=Path, default=DEFAULT_STUDY_TABLE)
    parser.add_argument(
        '--work', type=Path, help='work folder, kept (default: a temporary one, removed)'
    )
    parser.add_argument(
        '--reuse', action='store_true', help="keep the steps' results already in --work"
    )
    add_results_options(parser)
    return parser


def main() -> int:
    parser = build_parser()
    args = parser.parse_args()
    if args.reuse and args.work is None:
        parser.error('--reuse needs --work')
    kinds = [k.strip() for k in args.models.split(',') if k.strip()]
    work = (args.work or Path(tempfile.mkdtemp(prefix='generalisation-'))).resolve()
    work.mkdir(parents=True, exist_ok=True)
    print(f'work folder: {work}', file=sys.stderr, flush=True)
    started = time.perf_counter()
    unseen_bag, run, evaluation, loop = (work / n for n in ('unseen', 'run', 'eval', 'loop'))
    reuse = args.reuse
    table = study_table(args.study_table)
    steps: dict[str, dict[str, Any]] = {}

    steps['simulate'] = run_step(
        'simulate',
        cli('simulate', '--config', args.twin, '--seed', args.unseen_seed, '--robot-seed',
            args.robot_seed, '--duration', args.unseen_duration, '--out', unseen_bag,
            '--force', '--quiet'),
        work / 'simulate.log',
        unseen_bag / 'metadata.yaml' if reuse else None,
    )  # fmt: skip
    study = ['--study-table', args.study_table] if table['present'] else []
    steps['train'] = run_step(
        'train',
        cli('train', '--bag', args.bag, '--robot', args.robot, '--models', ','.join(kinds),
            '--max-seconds-per-model', args.max_seconds_per_model, '--out', run, *study,
            '--quiet', '--force'),
        work / 'train.log',
        run / 'metrics.json' if reuse else None,
    )  # fmt: skip
    if (run / 'metrics.json').is_file() and (unseen_bag / 'metadata.yaml').is_file():
        steps['evaluate'] = run_step(
            'evaluate',
            cli('evaluate', '--run', run, '--bag', unseen_bag, '--out', evaluation,
                '--quiet', '--force'),
            work / 'evaluate.log',
            evaluation / 'metrics.json' if reuse else None,
        )  # fmt: skip
        steps['closed-loop'] = run_step(
            'closed-loop',
            cli('closed-loop', '--run', run, '--bag', unseen_bag, '--out', loop, '--duration',
                args.closed_loop_seconds, '--quiet', '--force'),
            work / 'closed_loop.log',
            loop / 'closed_loop.json' if reuse else None,
        )  # fmt: skip

    run_metrics = read_json(run / 'metrics.json')
    evaluated = read_json(evaluation / 'metrics.json')
    if evaluated is None:
        print(f'no evaluation: the work folder {work} is kept', file=sys.stderr)
        return 1
    closed_loop = read_json(loop / 'closed_loop.json')
    document: dict[str, Any] = {
        'benchmark': NAME,
        'train_bag': str(args.bag),
        'twin_config': str(args.twin),
        'robot_config': str(args.robot),
        'unseen': {
            'seed': args.unseen_seed,
            'robot_seed': args.robot_seed,
            'duration_s': args.unseen_duration,
            'same_robot': same_robot(args.bag, unseen_bag),
            'evaluated_on': evaluated.get('evaluated_on'),
            'n_samples': evaluated.get('n_samples'),
        },
        'max_seconds_per_model': args.max_seconds_per_model,
        'kinds': [k for k in kinds if k in evaluated['models']],
        'joints': evaluated['joints'],
        'label_noise_floor_nm': evaluated.get('label_noise_floor_nm'),
        'failed_models': (run_metrics or {}).get('failed', {}),
        'cut_short': (run_metrics or {}).get('cut_short', {}),
        'models': model_figures(evaluated, run_metrics),
        'study_table': table,
        'steps': steps,
        'work': str(work) if args.work else None,
    }
    if closed_loop is not None:
        document['closed_loop'] = {
            'reference': closed_loop['reference'],
            'controller': closed_loop['controller'],
            'figures': loop_figures(closed_loop),
        }
    document['checks'] = acceptance(document)
    document['distance_to_rnea_id'] = distance_to_rnea_id(document['models'])
    document['wall_s'] = round(time.perf_counter() - started, 1)
    lines = report(document, settings_lines(NAME, parser, args))
    finish(NAME, document, lines, args)
    failed = any(s.get('returncode') for s in steps.values())
    if args.work is None and not failed:
        shutil.rmtree(work, ignore_errors=True)
    elif args.work is None:
        print(f'a step failed: the work folder {work} is kept', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
