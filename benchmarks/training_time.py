"""Wall time per model on the shipped bag (training, plus epochs and why each fit stopped), JSON.

    python benchmarks/training_time.py [--bag bags/default] [--models all]
        [--max-seconds-per-model S] [--out DIR]

Trains each model with ``train_run`` (the same path as ``id-learning train``) and reports, per
model, the fit's wall time, epochs, seconds per epoch and how it stopped. Without a budget the
models' own early stopping decides, which can take long on 2 cores; ``make demo`` uses 60 s.

Prints the table on stderr and the JSON document on stdout; writes docs/results/
training_time.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from common import (
    DEFAULT_BAG,
    DEFAULT_ROBOT,
    add_results_options,
    emit,
    markdown_table,
    number,
    publish_results,
    repo_path,
    settings_lines,
)

from id_learning.models.registry import STUDY_MODELS
from id_learning.robot import load_robot_config
from id_learning.training import train_run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bag', type=Path, default=DEFAULT_BAG)
    parser.add_argument('--robot', type=Path, default=DEFAULT_ROBOT)
    parser.add_argument('--target', choices=('motor', 'joint'), default='motor')
    parser.add_argument('--models', default=','.join(STUDY_MODELS))
    parser.add_argument('--max-seconds-per-model', type=float)
    parser.add_argument('--device', default='auto')
    parser.add_argument('--out', type=Path, help='keep the run here (default: a temp folder)')
    add_results_options(parser)
    args = parser.parse_args()
    kinds = [k.strip() for k in args.models.split(',') if k.strip()]
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or Path(scratch) / 'run'
        start = time.perf_counter()
        run = train_run(
            [args.bag],
            load_robot_config(args.robot),
            args.target,
            kinds,
            out,
            max_seconds_per_model=args.max_seconds_per_model,
            progress=False,
            device=args.device,
        )
        total = time.perf_counter() - start
        training_data = json.loads((out / 'run.json').read_text())['training_data']
    models = {}
    for kind, entry in run.metrics['models'].items():
        history = entry.get('history') or {}
        epochs = history.get('epochs')
        models[kind] = {
            'train_seconds': entry['train_seconds'],
            'epochs': epochs,
            'seconds_per_epoch': entry['train_seconds'] / epochs if epochs else None,
            'stopped_by': history.get('stopped_by'),
            'mean_rmse_normalised': entry['mean_rmse_normalised'],
        }
    document = {
        'benchmark': 'training_time',
        'bag': str(args.bag),
        'n_fit_samples': training_data['n_fit'],
        'n_validation_samples': training_data['n_validation'],
        'n_test_samples': run.metrics['n_samples'],
        'target': args.target,
        'max_seconds_per_model': args.max_seconds_per_model,
        'device': args.device,
        'run_wall_seconds': total,
        'models': models,
    }
    lines = report(document, settings_lines('training_time', parser, args))
    print('\n'.join(lines), file=sys.stderr)
    publish_results('training_time', document, lines, args)
    emit(document)


def report(document: dict, settings: list[str]) -> list[str]:
    """The results page's body: one row per model, its fit's wall time and how it stopped."""
    budget = document['max_seconds_per_model']
    rows = [
        [
            kind,
            number(m['train_seconds'], '.1f'),
            number(m['epochs'], 'd'),
            number(m['seconds_per_epoch'], '.2f'),
            m['stopped_by'] or '-',
            number(m['mean_rmse_normalised'], '.3g'),
        ]
        for kind, m in document['models'].items()
    ]
    return [
        "Wall time of each model's fit on the shipped bag, through `train_run` (the path of "
        f'`id-learning train`): bag `{repo_path(document["bag"])}`, target '
        f'`{document["target"]}`, device `{document["device"]}`, '
        + (
            f'at most {budget:g} s per model'
            if budget
            else "no time budget (each model's own early stopping decides)"
        )
        + f'; {document["n_fit_samples"]} fitting, {document["n_validation_samples"]} '
        f'validation and {document["n_test_samples"]} test samples. The whole run took '
        f"{document['run_wall_seconds']:.0f} s. Mean normalised RMSE: the run's own test "
        'figure, for context. No target is set here.',
        '',
        *settings,
        *markdown_table(
            [
                'model',
                'train time [s]',
                'epochs',
                'per epoch [s]',
                'stopped by',
                'mean normalised RMSE',
            ],
            rows,
            'lrrrlr',
        ),
    ]


if __name__ == '__main__':
    main()
