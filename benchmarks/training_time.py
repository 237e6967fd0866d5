"""Wall time per model on the shipped bag (training, plus epochs and why each fit stopped), JSON.

    python benchmarks/training_time.py [--bag bags/default] [--models all]
        [--max-seconds-per-model S] [--out DIR]

Trains each model with ``train_run`` (the same path as ``id-learning train``) and reports, per
model, the fit's wall time, epochs, seconds per epoch and how it stopped. Without a budget the
models' own early stopping decides, which can take long on 2 cores; ``make demo`` uses 60 s.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from common import DEFAULT_BAG, DEFAULT_ROBOT, emit

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
    emit(
        {
            'benchmark': 'training_time',
            'bag': str(args.bag),
            'n_fit_samples': training_data['n_fit'],
            'n_validation_samples': training_data['n_validation'],
            'n_test_samples': run.metrics['n_samples'],
            'target': args.target,
            'max_seconds_per_model': args.max_seconds_per_model,
            'run_wall_seconds': total,
            'models': models,
        }
    )


if __name__ == '__main__':
    main()
