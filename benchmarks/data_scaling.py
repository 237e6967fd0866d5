"""Test RMSE against the length of the training data: every kind on 5 to 40 min of one twin robot.

    python benchmarks/data_scaling.py [--seed 61] [--minutes 5,10,20,40] [--test-minutes 8]
        [--kinds all,...] [--seconds-per-model 120] [--out DIR] [--plot PATH]

Simulates one recording of max(--minutes) + --test-minutes (config/twin_default.yaml with the
seed: one robot, its hidden effects drawn once). For each duration D the D minutes just before
a common held-out tail make one bag whose training part they are (train fraction
D / (D + test)), so every model is judged on the same last minutes. Trains each kind through the
label filter (the default) and prints its test RMSE as a multiple of the label-noise floor per
joint and duration; plots it (one panel per joint) and ends with one JSON line; writes
docs/results/data_scaling.json and .md (not with ``--no-results``; ``--results-folder``
elsewhere).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Collection
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
    repo_path,
    settings_lines,
)

from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.models.registry import MODEL_KINDS
from id_learning.robot import load_robot_config
from id_learning.training import train_run
from id_learning.twin import load_twin_config, simulate, write_twin_output
from id_learning.twin.simulate import TwinResult


def last_samples(result: TwinResult, n: int) -> TwinResult:
    """The last n samples of a twin run, ground truth included."""
    if n > len(result.recording.stamps_ns):
        raise ValueError(f'the run holds {len(result.recording.stamps_ns)} samples, not {n}')
    return result.take(slice(len(result.recording.stamps_ns) - n, None))


def plot(
    minutes: list[float],
    ratios: dict[str, np.ndarray],
    joints: list[str],
    path: Path,
    cut_short: Collection[str] = (),
) -> None:
    """One panel per joint: test RMSE / floor against training minutes, a line per kind.

    A fit the time budget cut short (``cut_short`` holds ``'<kind>, <m> min'``) is ringed in red:
    its point is the budget's as much as the data's.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    columns = 3
    rows = -(-len(joints) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.2 * rows), squeeze=False)
    colours = [*plt.get_cmap('tab10').colors, 'black', 'dimgray']
    markers = 'osD^v<>phX*'
    for j, joint in enumerate(joints):
        ax = axes[j // columns][j % columns]
        for k, (kind, ratio) in enumerate(ratios.items()):
            style = {'color': colours[k % len(colours)], 'marker': markers[k % len(markers)]}
            ax.plot(minutes, ratio[:, j], label=kind, **style)
            cut = [i for i, m in enumerate(minutes) if f'{kind}, {m:g} min' in cut_short]
            ax.scatter(
                [minutes[i] for i in cut], ratio[cut, j], s=140, facecolors='none',
                edgecolors='red', linewidths=1.5, zorder=3,
            )  # fmt: skip
        ax.axhline(1.0, color='black', linewidth=0.8, linestyle='--')
        ax.set_xscale('log', base=2)
        ax.set_yscale('log')
        ax.set_xticks(minutes, [f'{m:g}' for m in minutes])
        ax.set_title(joint)
        ax.set_xlabel('training data [min]')
        ax.set_ylabel('test RMSE / noise floor')
    for k in range(len(joints), rows * columns):
        axes[k // columns][k % columns].axis('off')
    handles, labels = axes[0][0].get_legend_handles_labels()
    if cut_short:
        handles.append(
            plt.Line2D([], [], marker='o', color='red', markerfacecolor='none', linestyle='')
        )
        labels.append('cut short by the time budget')
    fig.legend(handles, labels, loc='lower center', ncol=min(6, len(labels)), fontsize='small')
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seed', type=int, default=61, help='twin seed (robot and recording)')
    parser.add_argument('--minutes', default='5,10,20,40', help='training durations [min]')
    parser.add_argument('--test-minutes', type=float, default=8.0, help='common held-out tail')
    parser.add_argument('--kinds', default=','.join(MODEL_KINDS), help='model kinds (all)')
    parser.add_argument('--seconds-per-model', type=float, default=120.0)
    parser.add_argument('--out', type=Path, help='keep the bags and the runs here')
    parser.add_argument('--plot', type=Path, default=REPO / 'out/benchmarks/data_scaling.png')
    parser.add_argument(
        '--replot', type=Path, metavar='JSON',
        help='only redraw --plot from a results document this benchmark wrote (its .json)',
    )  # fmt: skip
    add_results_options(parser)
    args = parser.parse_args()
    if args.replot is not None:
        replot(args.replot, args.plot)
        return
    minutes = sorted(float(m) for m in args.minutes.split(','))
    kinds = [k.strip() for k in args.kinds.split(',') if k.strip()]
    robot = load_robot_config(DEFAULT_ROBOT)
    began = time.monotonic()
    config = load_twin_config(REPO / 'config/twin_default.yaml', {'seed': args.seed})
    total_s = 60.0 * (minutes[-1] + args.test_minutes) + 30.0  # rests shorten the motion
    config = replace(config, excitation=replace(config.excitation, duration_s=total_s))
    print(f'simulating {total_s / 60:.0f} min (seed {args.seed}) ...', file=sys.stderr, flush=True)
    result = simulate(config)
    period = robot.ipo_period_s
    test_n = round(60.0 * args.test_minutes / period)
    ratios = {kind: np.zeros((len(minutes), robot.n_joints)) for kind in kinds}
    rmse: dict[str, list[list[float | None]]] = {kind: [] for kind in kinds}
    seconds: dict[str, list[float | None]] = {kind: [] for kind in kinds}
    floors = []
    failures: dict[str, str] = {}
    cut_short: dict[str, list[str]] = {}
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or Path(scratch)
        for i, m in enumerate(minutes):
            train_n = round(60.0 * m / period)
            bag = write_twin_output(
                last_samples(result, train_n + test_n), config, out / f'bag_{m:g}min',
                overwrite=True,
            )  # fmt: skip
            print(f'training {len(kinds)} kinds on {m:g} min ...', file=sys.stderr, flush=True)
            run = train_run(
                [bag],
                robot,
                'motor',
                kinds,
                out / f'run_{m:g}min',
                max_seconds_per_model=args.seconds_per_model,
                progress=False,
                device='cpu',
                overwrite=True,
                preprocess=PreprocessConfig(train_fraction=train_n / (train_n + test_n)),
            )
            floors.append(run.metrics['label_noise_floor_nm'])
            for kind in kinds:
                entry = run.metrics['models'].get(kind)
                if entry is None:  # its fit failed: a gap in its curve, with why
                    failures[f'{kind}, {m:g} min'] = run.failures.get(kind, 'not fitted')
                    ratios[kind][i] = np.nan
                    rmse[kind].append([None] * robot.n_joints)
                    seconds[kind].append(None)
                    continue
                ratios[kind][i] = entry['rmse_through_filter_over_floor']
                if kind in run.metrics.get('cut_short', {}):  # its figure is the budget's too
                    cut_short[f'{kind}, {m:g} min'] = run.metrics['cut_short'][kind]
                rmse[kind].append(entry['rmse_through_filter_nm'])
                seconds[kind].append(entry['train_seconds'])
    joints = list(robot.joints)
    plot(minutes, ratios, joints, args.plot, cut_short)
    for j, joint in enumerate(joints):
        print(f'\n{joint}: test RMSE / floor' + ''.join(f'{m:>9g} min' for m in minutes))
        for kind in kinds:
            print(f'  {kind:<28}' + ''.join(f'{x:>13.3g}' for x in ratios[kind][:, j]))
    print(f'\nfloor per duration [N*m]: {np.round(floors, 3).tolist()}; plot: {args.plot}')
    document: dict[str, Any] = {
        'benchmark': 'data_scaling',
        'seed': args.seed,
        'minutes': minutes,
        'test_minutes': args.test_minutes,
        'seconds_per_model': args.seconds_per_model,
        'joints': joints,
        'label_noise_floor_nm': floors,
        'rmse_through_filter_nm': rmse,
        'ratio_to_floor': {
            k: [[None if math.isnan(x) else x for x in row] for row in v.tolist()]
            for k, v in ratios.items()
        },
        'train_seconds': seconds,
        'failures': failures,
        'cut_short': cut_short,
        'wall_s': time.monotonic() - began,
        'plot': str(args.plot),
    }
    lines = report(document, settings_lines('data_scaling', parser, args))
    publish_results('data_scaling', document, lines, args)
    print(json.dumps({**document, 'environment': environment()}))


def replot(document_path: Path, path: Path) -> None:
    """Redraw the plot from a results document (``docs/results/data_scaling.json``)."""
    document = json.loads(document_path.read_text(encoding='utf-8'))
    ratios = {
        kind: np.array([[np.nan if x is None else x for x in row] for row in rows], dtype=float)
        for kind, rows in document['ratio_to_floor'].items()
    }
    plot(document['minutes'], ratios, document['joints'], path, document['cut_short'])
    print(f'plot: {path}')


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: the floor per duration, then per joint each kind's ratio."""
    minutes, joints = document['minutes'], document['joints']
    columns = [f'{m:g} min' for m in minutes]
    lines = [
        'Test RMSE against the length of the training data, on one twin robot '
        f'(config/twin_default.yaml, seed {document["seed"]}): for each duration the minutes '
        f'just before a common {document["test_minutes"]:g} min held-out tail make the training '
        'part, so every model is judged on the same last minutes. Each kind is trained through '
        f'the label filter (at most {document["seconds_per_model"]:g} s per model); its test '
        'RMSE through the filter is given as a multiple of the label-noise floor (1: as good '
        f'as the labels allow). Plot: `{repo_path(document["plot"])}`. Wall time '
        f'{document["wall_s"] / 60:.1f} min. No target is set here.',
        '',
        *settings,
        'Label-noise floor [N*m] per training duration:',
        '',
        *markdown_table(
            ['joint', *columns],
            [
                [joint, *(number(floor[j], '.3g') for floor in document['label_noise_floor_nm'])]
                for j, joint in enumerate(joints)
            ],
        ),
    ]
    for j, joint in enumerate(joints):
        rows = [
            [kind, *(number(ratio[i][j], '.3g') for i in range(len(minutes)))]
            for kind, ratio in document['ratio_to_floor'].items()
        ]
        lines += ['', f'{joint}: test RMSE / floor', '', *markdown_table(['kind', *columns], rows)]
    if document['failures']:
        lines += ['', 'Not fitted (a gap in the table and the plot):', '']
        lines += [f'- {where}: {why}' for where, why in document['failures'].items()]
    if document['cut_short']:
        lines += [
            '',
            "Cut short by the time budget (the figure is the budget's as much as the data's):",
            '',
        ]
        lines += [f'- {where}: {"; ".join(why)}' for where, why in document['cut_short'].items()]
    return lines


if __name__ == '__main__':
    main()
