"""The ``sweep`` subcommand: hyper-parameter search for one model kind on Optuna.

Start it in as many processes (or machines) as you like with the same ``--storage`` and
``--study-name``: they share one study. ``DIR/best.yaml`` is what ``train --hyper-file`` reads.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from id_learning.cli import options

__all__ = ['MAX_TRIALS', 'add_sweep_command', 'cmd_sweep']

#: The most trials one worker runs (start more workers on the same study for more).
MAX_TRIALS = 100_000


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run the worker's trials; print the study's best."""
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.training.sweep import run_sweep

    options.refuse_contradictions(args, [options.SPLIT_SEED_CONTRADICTION])
    robot = options.load_robot(args)
    result = run_sweep(
        options.bag_paths(args.bag),
        robot,
        args.target,
        args.model,
        Path(args.out),
        trials=args.trials,
        storage=args.storage,
        study_name=args.study_name,
        max_seconds_per_trial=args.max_seconds_per_trial,
        preprocess=PreprocessConfig(
            target=args.target,
            mode=args.preprocessing,
            split=args.split,
            split_seed=options.split_seed(args),
        ),
        progress=not args.quiet,
        seed=args.seed,
        trim_unpaired_tail=args.trim_unpaired_tail,
        storage_timeout_s=args.storage_timeout,
    )
    print(
        f'study {result.study_name} ({result.storage}): {result.finished} finished trials; '
        f'best validation error {result.best_value:.4g} with {result.best_params}'
    )
    print(f'best: {result.best_file} (train --hyper-file {result.best_file})')
    for figure in result.figures:
        print(f'figure: {figure}')
    return 0


def add_sweep_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``sweep`` to the subcommands ``sub``."""
    p = sub.add_parser(
        'sweep', help="search a model kind's hyper-parameters on Optuna (shareable study)"
    )
    p.add_argument('--bag', required=True, action='append', help='bag folder (repeatable)')
    options.robot_option(p)
    options.target_option(p)
    options.preprocessing_option(p)
    options.split_option(p)
    p.add_argument('--model', required=True, help='the model kind to sweep, e.g. mlp')
    p.add_argument(
        '--trials',
        type=options.integer(1, MAX_TRIALS),
        default=20,
        help=f'trials this worker runs (20; at most {MAX_TRIALS})',
    )
    p.add_argument(
        '--storage',
        help='Optuna storage URL shared by the workers (default: sqlite:///OUT/sweep.db; '
        'postgresql+psycopg://user@host/db for several machines)',
    )
    p.add_argument(
        '--storage-timeout',
        type=options.finite(0.0, 3600.0, low_open=True),
        default=10.0,
        metavar='SECONDS',
        help='wait at most this long for a locked SQLite file or an unreachable server before '
        'giving up (10)',
    )
    p.add_argument(
        '--study-name', type=options.non_empty_name, help='the study (default: KIND-TARGET)'
    )
    p.add_argument('--out', required=True, help='folder for best.yaml, plots and the SQLite db')
    p.add_argument(
        '--max-seconds-per-trial',
        type=options.fit_seconds,
        help='wall-clock budget of each network fit [s]',
    )
    p.add_argument('--seed', type=options.seed, help="the sampler's seed (default: random)")
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    options.trim_option(p)
    p.set_defaults(func=cmd_sweep)
