"""Our DeLaN and LNN on the DeLaN "character" benchmark: test torque MSE and wall time, as JSON.

The data (a simulated 2-DoF planar arm writing 20 characters, Lutter et al. 2019) are not part of
the project: pass the folder or the .npz converted from the reference implementation with
``--data``. Protocol of the reference: train on 17 characters, test on 'e', 'q' and 'v'. The
reference has no validation part (it trains a fixed number of epochs), so the loss on the whole
training set stands in for the validation loss: the kept weights are those of the epoch with the
lowest training loss, and the test characters are never looked at while training.

The metric is the reference's own: the squared torque error summed over the two joints,
averaged over the test samples, one figure per seed, and the median over the seeds
(``test_mse_sum_joints_median``), beside the reference's shipped 10-seed medians. The wall time
of one seed (build, train, evaluate) is compared with the reference's timed single runs.

Training (``SETTINGS``): Adam with a step schedule, the learning rate divided by about 3 at 40 %,
67 % and 87 % of the epochs (each step a fresh ``train_module`` call from the best weights so
far). The LNN's weights are drawn fan-in scaled (``init='fan_in'``: truncated normal, std
1/sqrt(fan_in), as the reference's haiku layers are) instead of AnalyticMLP's default
Xavier-uniform: with 4 inputs and 64
units Xavier draws the first layer about 3 times smaller, its tanh units start almost linear,
and within the same epochs the LNN fits the training set about half as well (training loss 2x).

    python benchmarks/delan_character.py --data ../shared/data/delan_character [--seeds 5]

Prints one JSON document and writes docs/results/delan_character.json and .md (not with
``--no-results``; ``--results-folder`` elsewhere); with no data at the path it prints
{"skipped": reason}, writes nothing and exits 0. Progress and the table go to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from common import (
    REPO,
    add_results_options,
    environment,
    markdown_table,
    number,
    publish_results,
    repo_path,
    settings_lines,
    verdict,
)

from id_learning.models.fitting import OptimConfig, configure_torch, train_module
from id_learning.models.lagrangian import (
    DelanConfig,
    DelanNetwork,
    LagrangianScaling,
    LnnConfig,
    LnnNetwork,
)
from id_learning.models.torch_utils import normalised_mse, to_numpy, to_tensor

DEFAULT_DATA = REPO.parent / 'shared' / 'data' / 'delan_character'
DATA_FILE = 'character_data.npz'
TEST_CHARACTERS = ('e', 'q', 'v')
_SOURCE = '../shared/data/delan_character/README.md'

#: The reference's figures on this split, from the README beside the data (2-core CPU machine).
#: ``test_mse_sum_joints_median``: the stored results shipped with the reference, median of 10
#: seeds; ``timed_run``: one run timed on such a machine (the wall time we compare with).
REFERENCE: dict[str, dict[str, Any]] = {
    'delan': {
        'test_mse_sum_joints_median': 2.1e-5,
        'seeds': 10,
        'timed_run': {
            'run': 'JAX DeLaN structured, 5,000 epochs',
            'test_mse_sum_joints': 3.8e-5,
            'wall_s': 182.0,
        },
        'source': f'{_SOURCE}, table "Reference results"',
    },
    'lnn': {
        'test_mse_sum_joints_median': 2.8e-5,
        'seeds': 10,
        'timed_run': {
            'run': 'JAX DeLaN black box (an LNN), 5,000 epochs',
            'test_mse_sum_joints': 7.0e-5,
            'wall_s': 354.0,
        },
        'source': f'{_SOURCE}, table "Reference results"',
    },
}

#: Our training per model (see the module docstring); both 2 x 64 tanh, as the reference; the
#: energy balance is ``train``'s default.
SETTINGS: dict[str, dict[str, Any]] = {
    'delan': {
        'epochs': 1500,
        'init': 'xavier',
        'activation': 'tanh',
        'energy_balance': DelanConfig().energy_balance,
    },
    'lnn': {
        'epochs': 2500,
        'init': 'fan_in',
        'activation': 'tanh',
        'energy_balance': LnnConfig().energy_balance,
    },
}

#: Step schedule: (learning-rate factor, share of the epochs).
LR_STEPS = ((1.0, 0.4), (1 / 3, 0.27), (0.1, 0.2), (1 / 30, 0.13))


def load_split(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """Train / test arrays (N, 2) by the reference's character split."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {key: data[key] for key in ('qp', 'qv', 'qa', 'tau', 'labels', 'lengths')}
    owner = np.repeat(arrays['labels'], arrays['lengths'])
    is_test = np.isin(owner, TEST_CHARACTERS)
    names = {'q': 'qp', 'v': 'qv', 'a': 'qa', 'tau': 'tau'}
    return {
        part: {name: arrays[key][rows].astype(float) for name, key in names.items()}
        for part, rows in (('train', ~is_test), ('test', is_test))
    }


def mse_sum_joints(predicted: np.ndarray, target: np.ndarray) -> float:
    """The reference's metric: squared error summed over joints, averaged over samples."""
    return float(np.mean(np.sum((np.asarray(predicted) - np.asarray(target)) ** 2, axis=1)))


def schedule(learning_rate: float, epochs: int) -> list[tuple[float, int]]:
    """(learning rate, epochs) per step of LR_STEPS; the last step takes what is left."""
    steps = [
        (float(f'{learning_rate * factor:.3g}'), round(epochs * share))
        for factor, share in LR_STEPS
    ]
    steps[-1] = (steps[-1][0], epochs - sum(n for _, n in steps[:-1]))
    return [(rate, n) for rate, n in steps if n > 0]


def run_seed(
    kind: str, split: dict[str, dict[str, np.ndarray]], args: argparse.Namespace, seed: int
) -> dict[str, Any]:
    """Train one network from scratch and evaluate it on the test characters."""
    start, start_cpu = time.perf_counter(), time.process_time()
    settings = model_settings(kind, args)
    train, test = split['train'], split['test']
    scaling = LagrangianScaling.from_data(
        train['q'], train['v'], train['tau'], balance=settings['energy_balance']
    )
    generator = torch.Generator().manual_seed(seed)
    network: torch.nn.Module
    if kind == 'delan':
        network = DelanNetwork(
            scaling,
            activation=settings['activation'],
            generator=generator,
            init=settings['init'],
        )
    else:
        network = LnnNetwork(
            scaling,
            activation=settings['activation'],
            generator=generator,
            init=settings['init'],
        )
    tensors = [to_tensor(train[name]) for name in ('q', 'v', 'a', 'tau')]
    scale = to_tensor(scaling.torque.scale())

    def loss(q: torch.Tensor, v: torch.Tensor, a: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        return normalised_mse(network(q, v, a), tau, scale)

    train_loss = float('nan')
    for step, (rate, epochs) in enumerate(settings['learning_rate_steps']):
        optim = OptimConfig(
            learning_rate=rate,
            batch_size=args.batch_size,
            max_epochs=epochs,
            patience=epochs,
            seed=seed * len(LR_STEPS) + step,
        )
        history = train_module(network, loss, tensors, tensors, optim, description=kind)
        train_loss = history.best_validation_loss
    network.eval()
    with torch.inference_mode():
        predicted = to_numpy(network(*(to_tensor(test[name]) for name in ('q', 'v', 'a'))))
    wall = time.perf_counter() - start
    return {
        'test_mse_sum_joints': mse_sum_joints(predicted, test['tau']),
        'test_mse_per_joint': np.mean((predicted - test['tau']) ** 2, axis=0).tolist(),
        'train_loss_normalised': train_loss,
        'wall_s': round(wall, 2),
        'cpu_s': round(time.process_time() - start_cpu, 2),
    }


def model_settings(kind: str, args: argparse.Namespace) -> dict[str, Any]:
    """SETTINGS[kind] with the command line's overrides, and its (learning rate, epochs) steps."""
    settings = dict(SETTINGS[kind])
    for key in ('epochs', 'init', 'activation', 'energy_balance'):
        value = getattr(args, f'{kind}_{key}')
        if value is not None:
            settings[key] = value
    settings['learning_rate_steps'] = schedule(args.learning_rate, settings['epochs'])
    return settings


def summarise(kind: str, runs: list[dict[str, Any]], seeds: list[int]) -> dict[str, Any]:
    """Per-seed figures, their medians and the comparison with the reference (strictly better)."""
    mse = [run['test_mse_sum_joints'] for run in runs]
    wall = [run['wall_s'] for run in runs]
    reference = REFERENCE[kind]
    mse_median, wall_median = float(np.median(mse)), float(np.median(wall))
    return {
        'seeds': seeds,
        'test_mse_sum_joints_median': mse_median,
        'test_mse_sum_joints_per_seed': mse,
        'test_mse_per_joint_median': np.median(
            [run['test_mse_per_joint'] for run in runs], axis=0
        ).tolist(),
        'wall_s_median': round(wall_median, 2),
        'wall_s_per_seed': wall,
        'cpu_s_per_seed': [run['cpu_s'] for run in runs],
        'train_loss_normalised_per_seed': [run['train_loss_normalised'] for run in runs],
        'reference': reference,
        'ratio_to_reference_mse': round(mse_median / reference['test_mse_sum_joints_median'], 3),
        'ratio_to_reference_time': round(wall_median / reference['timed_run']['wall_s'], 3),
        'beats_reference_mse': mse_median < reference['test_mse_sum_joints_median'],
        'beats_reference_time': wall_median < reference['timed_run']['wall_s'],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--data', type=Path, default=DEFAULT_DATA, help='folder or .npz file')
    parser.add_argument('--seeds', type=int, default=5, help='seeds per model (median over them)')
    parser.add_argument('--first-seed', type=int, default=0)
    parser.add_argument('--models', default='delan,lnn', help='comma-separated: delan, lnn')
    parser.add_argument('--batch-size', type=int, default=256)
    parser.add_argument('--learning-rate', type=float, default=3e-3, help='before the steps')
    for kind, defaults in SETTINGS.items():
        parser.add_argument(f'--{kind}-epochs', type=int, help=f'default {defaults["epochs"]}')
        parser.add_argument(f'--{kind}-init', choices=('xavier', 'fan_in'))
        parser.add_argument(f'--{kind}-activation', choices=('tanh', 'softplus'))
        parser.add_argument(
            f'--{kind}-energy-balance',
            type=float,
            help=f"default {defaults['energy_balance']} (train's)",
        )
    parser.add_argument(
        '--threads', type=int, default=1, help='torch threads (the networks are too small to gain)'
    )
    add_results_options(parser)
    args = parser.parse_args(argv)
    kinds = args.models.split(',')
    for kind in kinds:
        if kind not in REFERENCE:
            parser.error(f'unknown model {kind!r}; known: {sorted(REFERENCE)}')
    if args.seeds < 1:
        parser.error('--seeds must be >= 1')

    path = args.data / DATA_FILE if args.data.is_dir() else args.data
    if not path.is_file():
        reason = f'no benchmark data at {path}'
        print(f'delan_character: skipped, {reason}; nothing written', file=sys.stderr)
        print(json.dumps({'skipped': reason}))
        return 0
    configure_torch(args.threads)
    split = load_split(path)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    results: dict[str, Any] = {
        'benchmark': 'delan_character',
        'data': str(path),
        'train_samples': len(split['train']['q']),
        'test_samples': len(split['test']['q']),
        'metric': 'test torque MSE summed over joints, mean over test samples, median over seeds',
        'settings': {
            'batch_size': args.batch_size,
            'threads': args.threads,
            **{kind: model_settings(kind, args) for kind in kinds},
        },
        'models': {},
    }
    for kind in kinds:
        runs = []
        for seed in seeds:
            runs.append(run_seed(kind, split, args, seed))
            print(
                f'{kind} seed {seed}: test MSE (sum over joints) '
                f'{runs[-1]["test_mse_sum_joints"]:.3e}, {runs[-1]["wall_s"]:.1f} s',
                file=sys.stderr,
                flush=True,
            )
        results['models'][kind] = summarise(kind, runs, seeds)
    lines = report(results, settings_lines('delan_character', parser, args))
    print('\n'.join(lines), file=sys.stderr)
    publish_results('delan_character', results, lines, args)
    results.update(environment())
    print(json.dumps(results, indent=2))
    return 0


def report(results: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: per model the median test MSE and wall time, and the reference."""
    rows = []
    for kind, model in results['models'].items():
        reference = model['reference']
        rows.append(
            [
                kind,
                len(model['seeds']),
                number(model['test_mse_sum_joints_median'], '.2e'),
                number(reference['test_mse_sum_joints_median'], '.2e'),
                number(model['ratio_to_reference_mse'], '.3g'),
                verdict(model['beats_reference_mse']),
                number(model['wall_s_median'], '.1f'),
                number(reference['timed_run']['wall_s'], '.0f'),
                verdict(model['beats_reference_time']),
            ]
        )
    schedules = '; '.join(
        f'{kind}: {settings_used["epochs"]} epochs, init {settings_used["init"]}, '
        f'{settings_used["activation"]}, energy balance {settings_used["energy_balance"]:g}, '
        'learning rate '
        + ' / '.join(f'{rate:g} x {n}' for rate, n in settings_used['learning_rate_steps'])
        for kind, settings_used in results['settings'].items()
        if kind in results['models']
    )
    return [
        'Our DeLaN and LNN on the DeLaN "character" benchmark (a simulated 2-DoF planar arm '
        f"writing characters; data `{repo_path(results['data'])}`), with the reference's split "
        f'(test on {", ".join(TEST_CHARACTERS)}, {results["test_samples"]} samples; train on '
        f'the other characters, {results["train_samples"]} samples) and metric: the squared '
        'torque error summed over the two joints, averaged over the test samples [(N*m)^2], '
        'median over the seeds. Wall '
        'time: one seed (build, train, evaluate), median over the seeds, against the '
        "reference's timed single run on a 2-core CPU machine. Batch "
        f'{results["settings"]["batch_size"]}, {results["settings"]["threads"]} torch '
        f'thread(s); {schedules}.',
        '',
        *settings,
        'Target: strictly better than the reference (its shipped 10-seed median; its timed run).',
        '',
        *markdown_table(
            [
                'model',
                'seeds',
                'test MSE median [(N*m)^2]',
                'reference [(N*m)^2]',
                'ratio',
                'MSE target',
                'wall median [s]',
                'reference [s]',
                'time target',
            ],
            rows,
            'lrrrrlrrl',
        ),
    ]


if __name__ == '__main__':
    sys.exit(main())
