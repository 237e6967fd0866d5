"""Our DeLaN and LNN on the DeLaN "character" benchmark: test torque MSE and wall time, as JSON.

The data (a simulated 2-DoF planar arm writing 20 characters, Lutter et al. 2019) are not part of
the project: pass the folder or the .npz converted from the reference implementation with
``--data``. Protocol of the reference: train on 17 characters, test on 'e', 'q' and 'v'. The
reference has no validation part (it trains a fixed number of epochs), so the loss on the whole
training set stands in for the validation loss: the kept weights are those of the epoch with the
lowest training loss, and the test characters are never looked at while training.

    python benchmarks/delan_character.py --data ../shared/data/delan_character [--epochs N]

Prints one JSON document; with no data at the path it prints {"skipped": reason} and exits 0.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from id_learning.models.fitting import OptimConfig, configure_torch, train_module
from id_learning.models.lagrangian import DelanNetwork, LagrangianScaling, LnnNetwork
from id_learning.models.torch_utils import normalised_mse, to_numpy, to_tensor

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = REPO.parent / 'shared' / 'data' / 'delan_character'
DATA_FILE = 'character_data.npz'
TEST_CHARACTERS = ('e', 'q', 'v')

#: From the README beside the data: test torque MSE and wall time on a 2-core CPU machine.
REFERENCE = {
    'delan': {'run': 'JAX DeLaN structured, 5,000 epochs', 'test_mse': 3.8e-5, 'wall_s': 182.0},
    'lnn': {'run': 'JAX DeLaN black box, 5,000 epochs', 'test_mse': 7.0e-5, 'wall_s': 354.0},
}


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


def run_model(
    kind: str, split: dict[str, dict[str, np.ndarray]], args: argparse.Namespace
) -> dict[str, Any]:
    """Train one network from scratch and evaluate it on the test characters."""
    start, start_cpu = time.perf_counter(), time.process_time()
    train, test = split['train'], split['test']
    scaling = LagrangianScaling.from_data(train['q'], train['v'], train['tau'])
    generator = torch.Generator().manual_seed(args.seed)
    if kind == 'delan':
        network: torch.nn.Module = DelanNetwork(
            scaling, activation=args.delan_activation, generator=generator
        )
    else:
        network = LnnNetwork(scaling, activation=args.lnn_activation, generator=generator)
    tensors = [to_tensor(train[name]) for name in ('q', 'v', 'a', 'tau')]
    scale = to_tensor(scaling.torque.scale())

    def loss(q: torch.Tensor, v: torch.Tensor, a: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        return normalised_mse(network(q, v, a), tau, scale)

    optim = OptimConfig(
        learning_rate=args.learning_rate,
        batch_size=args.batch_size,
        max_epochs=args.epochs,
        patience=args.epochs,
        seed=args.seed,
    )
    history = train_module(network, loss, tensors, tensors, optim, description=kind)
    network.eval()
    with torch.inference_mode():
        predicted = to_numpy(network(*(to_tensor(test[name]) for name in ('q', 'v', 'a'))))
    wall = time.perf_counter() - start
    cpu = time.process_time() - start_cpu
    squared = (predicted - test['tau']) ** 2
    reference = REFERENCE[kind]
    mse = float(np.mean(squared))
    return {
        'test_mse': mse,
        'test_mse_summed_over_joints': float(np.mean(np.sum(squared, axis=1))),
        'test_mse_per_joint': np.mean(squared, axis=0).tolist(),
        'wall_s': round(wall, 2),
        'cpu_s': round(cpu, 2),
        'epochs': len(history.train_loss),
        'best_epoch': history.best_epoch,
        'final_train_loss_normalised': history.train_loss[-1],
        'reference': reference,
        'beats_reference_mse': mse <= reference['test_mse'],
        'faster_than_reference': wall < reference['wall_s'],
    }


def machine() -> dict[str, Any]:
    """Where the figures were taken."""
    try:
        commit = subprocess.run(
            ['git', 'rev-parse', 'HEAD'], capture_output=True, text=True, cwd=REPO, check=False
        ).stdout.strip()
    except OSError:
        commit = ''
    return {
        'host': platform.node(),
        'cpu_count': os.cpu_count(),
        'torch_threads': torch.get_num_threads(),
        'load_average_1min': round(os.getloadavg()[0], 2),
        'device': 'cpu',
        'python': platform.python_version(),
        'torch': torch.__version__,
        'commit': commit or None,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--data', type=Path, default=DEFAULT_DATA, help='folder or .npz file')
    parser.add_argument('--epochs', type=int, default=1500)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--models', default='delan,lnn', help='comma-separated: delan, lnn')
    parser.add_argument('--batch-size', type=int, default=256)
    parser.add_argument('--learning-rate', type=float, default=3e-3)
    parser.add_argument('--delan-activation', default='tanh')
    parser.add_argument('--lnn-activation', default='tanh')
    parser.add_argument(
        '--threads', type=int, default=1, help='torch threads (the networks are too small to gain)'
    )
    args = parser.parse_args(argv)

    path = args.data / DATA_FILE if args.data.is_dir() else args.data
    if not path.is_file():
        print(json.dumps({'skipped': f'no benchmark data at {path}'}))
        return 0
    configure_torch(args.threads)
    split = load_split(path)
    results: dict[str, Any] = {
        'benchmark': 'delan_character',
        'data': str(path),
        'train_samples': len(split['train']['q']),
        'test_samples': len(split['test']['q']),
        'settings': {
            key: getattr(args, key)
            for key in (
                'epochs',
                'seed',
                'batch_size',
                'learning_rate',
                'delan_activation',
                'lnn_activation',
                'threads',
            )
        },
        'machine': machine(),
        'models': {},
    }
    for kind in args.models.split(','):
        if kind not in REFERENCE:
            parser.error(f'unknown model {kind!r}; known: {sorted(REFERENCE)}')
        results['models'][kind] = run_model(kind, split, args)
    print(json.dumps(results, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
