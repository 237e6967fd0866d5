"""Every kind trained both ways (through the label filter, the study's way) on a fresh twin seed.

    python benchmarks/filter_consistency.py [--seed 31] [--duration 600] [--kinds all,...]
        [--seconds-per-model 60] [--out DIR]

Simulates a twin recording (config/twin_default.yaml with the given seed), trains each kind
with ``--preprocessing through_filter`` (the default) and with ``--preprocessing study``, and
scores every model the same way, independently of the run's own metrics: ``load_model``, the
torque on a controller's inputs (recorded q, recorded v smoothed at the robot's input smoothing,
a by central differences) along the whole recording, low-passed like the labels (scipy), against
the labels and against the noise-free torque on the test part. Prints per kind and way the test
RMSE through the filter and against the truth as multiples of the label-noise floor, checks
metrics.json against the independent scoring, and ends with one JSON line; writes docs/results/
filter_consistency.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    DEFAULT_ROBOT,
    REPO,
    add_results_options,
    environment,
    markdown_table,
    number,
    publish_results,
    settings_lines,
    verdict,
)

from id_learning.dataset.preprocess import PreprocessConfig, prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.dataset.signals import lowpass
from id_learning.models.registry import MODEL_KINDS, load_model
from id_learning.robot import load_robot_config
from id_learning.training import train_run
from id_learning.twin import load_twin_config, simulate, write_twin_output

WAYS = ('through_filter', 'study')
#: metrics.json's RMSE through the filter and the independent scoring agree within this
#: (relative, worst joint).
AGREEMENT = 1e-3


def rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=0))


def independent_scores(run: Path, bag: Path, robot: Any, kinds: list[str]) -> dict[str, Any]:
    """Per kind: RMSE through the filter against labels and truth, and the floor [N*m]."""
    recording = load_recording(bag, robot)
    dataset = prepare_dataset(recording, robot)
    with np.load(bag / 'ground_truth.npz') as arrays:
        clean = arrays['tau_u_clean'].astype(float)
    period, cutoff = robot.ipo_period_s, robot.lowpass_cutoff_hz
    velocity = lowpass(recording.velocity, robot.input_smoothing_hz, period)
    q, v = recording.position, velocity
    a = np.gradient(v, period, axis=0, edge_order=2)
    test = slice(dataset.n_train, None)
    clean_filtered = lowpass(clean, cutoff, period)
    out: dict[str, Any] = {'floor': rms(dataset.tau[test] - clean_filtered[test])}
    for kind in kinds:
        model = load_model(run / 'models' / kind, robot, kind)
        filtered = lowpass(model.predict(q, v, a), cutoff, period)
        out[kind] = {
            'label': rms(filtered[test] - dataset.tau[test]),
            'truth': rms(filtered[test] - clean_filtered[test]),
        }
    return out


def table(title: str, rows: dict[str, np.ndarray], joints: list[str]) -> str:
    lines = [f'{title:<34}' + ''.join(f'{j:>9}' for j in joints)]
    lines += [
        f'{name:<34}' + ''.join(f'{x:>9.3g}' for x in values) for name, values in rows.items()
    ]
    return '\n'.join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seed', type=int, default=31, help='twin seed (robot and recording)')
    parser.add_argument('--duration', type=float, default=600.0, help='recording length [s]')
    parser.add_argument(
        '--kinds',
        default=','.join(MODEL_KINDS),
        help='comma-separated model kinds (default: every kind)',
    )
    parser.add_argument('--seconds-per-model', type=float, default=60.0)
    parser.add_argument('--out', type=Path, help='keep the bag and the runs here')
    add_results_options(parser)
    args = parser.parse_args()
    kinds = [k.strip() for k in args.kinds.split(',') if k.strip()]
    began = time.monotonic()
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or Path(scratch)
        config = load_twin_config(REPO / 'config/twin_default.yaml', {'seed': args.seed})
        excitation = replace(config.excitation, duration_s=args.duration)
        config = replace(config, excitation=excitation)
        bag = write_twin_output(simulate(config), config, out / 'bag', overwrite=True)
        robot = load_robot_config(DEFAULT_ROBOT)
        runs, scores, train_seconds, agreement = {}, {}, {}, {}
        for way in WAYS:
            print(f'training {len(kinds)} kinds the {way} way ...', file=sys.stderr, flush=True)
            run = train_run(
                [bag],
                robot,
                'motor',
                kinds,
                out / way,
                max_seconds_per_model=args.seconds_per_model,
                progress=False,
                device='cpu',
                overwrite=True,
                preprocess=PreprocessConfig(mode=way),
            )
            runs[way] = run.metrics
            scores[way] = independent_scores(out / way, bag, robot, kinds)
            train_seconds[way] = {k: run.metrics['models'][k]['train_seconds'] for k in kinds}
            agreement[way] = {
                k: float(
                    np.max(
                        np.abs(
                            np.asarray(run.metrics['models'][k]['rmse_through_filter_nm'])
                            / scores[way][k]['label']
                            - 1
                        )
                    )
                )
                for k in kinds
            }
    floor = scores['through_filter']['floor']
    joints = list(robot.joints)
    print(table('label-noise floor [N*m]', {'floor': floor}, joints))
    for key, title in (
        ('label', 'through the filter / floor'),
        ('truth', 'vs noise-free / floor'),
    ):
        rows = {
            f'{kind} ({way})': scores[way][kind][key] / floor for kind in kinds for way in WAYS
        }
        print()
        print(table(title, rows, joints))
    print()
    print(
        'metrics.json vs independent scoring, max relative difference: '
        + ', '.join(f'{k} {max(agreement[w][k] for w in WAYS):.1e}' for k in kinds)
    )
    result = {
        'benchmark': 'filter_consistency',
        'seed': args.seed,
        'duration_s': args.duration,
        'seconds_per_model': args.seconds_per_model,
        'joints': joints,
        'label_noise_floor_nm': floor.tolist(),
        'ratio_through_filter': {
            way: {k: (scores[way][k]['label'] / floor).tolist() for k in kinds} for way in WAYS
        },
        'ratio_truth_through_filter': {
            way: {k: (scores[way][k]['truth'] / floor).tolist() for k in kinds} for way in WAYS
        },
        'metrics_agreement_max_relative': agreement,
        'train_seconds': train_seconds,
        'wall_s': time.monotonic() - began,
    }
    lines = report(result, settings_lines('filter_consistency', parser, args))
    publish_results('filter_consistency', result, lines, args)
    print(json.dumps({**result, 'environment': environment()}))


def report(result: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: the floor, both ratios per kind and way, the agreement."""
    joints = result['joints']
    kinds = list(result['train_seconds'][WAYS[0]])
    lines = [
        'Every kind trained both ways on one fresh twin recording (config/twin_default.yaml, '
        f'seed {result["seed"]}, {result["duration_s"]:g} s, at most '
        f'{result["seconds_per_model"]:g} s per model): through the label filter (the default) '
        "and the study's way. Every model is scored alike and independently of the run's own "
        "metrics: its torque on a controller's inputs along the whole recording, low-passed like "
        'the labels, against the labels and against the noise-free torque on the test part, as '
        'multiples of the label-noise floor (1: as good as the labels allow). Wall time '
        f'{result["wall_s"] / 60:.1f} min.',
        '',
        *settings,
        *markdown_table(
            ['', *joints],
            [
                [
                    'label-noise floor [N*m]',
                    *(number(x, '.3g') for x in result['label_noise_floor_nm']),
                ]
            ],
        ),
    ]
    for key, title in (
        ('ratio_through_filter', 'Test RMSE through the filter against the labels / floor'),
        ('ratio_truth_through_filter', 'Test RMSE through the filter against the truth / floor'),
    ):
        rows = [
            [f'{kind} ({way})', *(number(x, '.3g') for x in result[key][way][kind])]
            for kind in kinds
            for way in WAYS
        ]
        lines += ['', f'{title}:', '', *markdown_table(['kind (way)', *joints], rows)]
    agreement = result['metrics_agreement_max_relative']
    rows = []
    for kind in kinds:
        worst = max(agreement[way][kind] for way in WAYS)
        rows.append(
            [
                kind,
                *(number(agreement[way][kind], '.1e') for way in WAYS),
                verdict(worst <= AGREEMENT),
            ]
        )
    lines += [
        '',
        "metrics.json's RMSE through the filter against this independent scoring, largest "
        f'relative difference over the joints; target: within {AGREEMENT:g}.',
        '',
        *markdown_table(['kind', *WAYS, 'target'], rows, 'lrrl'),
    ]
    return lines


if __name__ == '__main__':
    main()
