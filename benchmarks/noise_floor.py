"""Each model's test RMSE through the label filter as a multiple of the twin's label-noise floor.

    python benchmarks/noise_floor.py [--run out/demo/run]

The run must have been trained on twin bags (their folders hold ground_truth.npz). Everything is
recomputed from the bags with the run's stored preprocessing and the saved models
(``evaluation.scoring``): each model's torque along each whole recording on the controller's
inputs, low-passed like the labels, against the labels on the test part; the floor is the
filtered label minus the filtered noise-free torque on the same rows. A ratio near 1 means the
model is as good as the labels allow. The best model is the one with the lowest mean normalised
test RMSE (the per-joint best is reported too). Where the bags' twin config rebuilds the planned
motion (``twin.needed_torque``), each model's error against the torque the drive needs (on the
planned reference, without the label's delay, unfiltered) is given over the same floor too.

Prints the table on stderr and the JSON document on stdout; writes docs/results/noise_floor.json
and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from common import (
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    repo_path,
    settings_lines,
)

from id_learning.errors import DatasetError
from id_learning.evaluation.scoring import label_noise_floor, score_model
from id_learning.models.registry import load_model
from id_learning.robot import load_robot_config
from id_learning.training.trainer import (
    combine_datasets,
    load_datasets,
    preprocess_from_dict,
    read_run,
)
from id_learning.twin.needed_torque import NEEDED_TORQUE_NOTES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--run', type=Path, default=REPO / 'out/demo/run')
    add_results_options(parser)
    args = parser.parse_args()
    run = read_run(args.run)
    robot = load_robot_config(run['robot_config'])
    config = preprocess_from_dict(run['preprocessing'])
    bags = [Path(entry['path']) for entry in run['training_data']['bags']]
    dataset = combine_datasets(load_datasets(bags, robot, config, progress=False))
    floor = label_noise_floor(dataset)
    if floor is None:
        raise DatasetError(f'{bags}: no ground_truth.npz; the noise floor needs twin bags')
    scale = dataset.target_scaler.scale()
    rmse, needed = {}, {}
    for kind in run['kinds']:
        model = load_model(args.run / 'models' / kind, robot, kind)
        metrics = score_model(model, dataset, scale).metrics
        rmse[kind] = np.asarray(metrics['rmse_nm'])
        if 'rmse_needed_over_floor' in metrics:
            needed[kind] = metrics['rmse_needed_over_floor']
    best = min(rmse, key=lambda k: float(np.mean(rmse[k] / scale)))
    per_joint_best = [min(rmse, key=lambda k, j=j: rmse[k][j]) for j in range(robot.n_joints)]
    document = {
        'benchmark': 'noise_floor',
        'run': str(args.run),
        'target': config.target,
        'preprocessing': config.mode,
        'joints': list(robot.joints),
        'label_noise_rms_nm': floor.tolist(),
        'best_model': best,
        'best_rmse_through_filter_nm': rmse[best].tolist(),
        'best_ratio_to_noise': (rmse[best] / floor).tolist(),
        'per_joint_best_model': per_joint_best,
        'per_joint_best_ratio_to_noise': [
            float(rmse[k][j] / floor[j]) for j, k in enumerate(per_joint_best)
        ],
        'ratio_to_noise_by_model': {k: (v / floor).tolist() for k, v in rmse.items()},
        'needed_ratio_to_noise_by_model': needed,
        'needed_torque_notes': dataset.extra.get(NEEDED_TORQUE_NOTES) or [],
        'bags': [str(bag) for bag in bags],
    }
    lines = report(document, settings_lines('noise_floor', parser, args))
    finish('noise_floor', document, lines, args)


def report(document: dict, settings: list[str]) -> list[str]:
    """The results page's body: the floor per joint, each model's ratio, the best ones."""
    joints = document['joints']
    rows = [
        [f'**{kind}**' if kind == document['best_model'] else kind]
        + [number(x, '.3g') for x in ratios]
        for kind, ratios in document['ratio_to_noise_by_model'].items()
    ]
    return [
        "Each model's test RMSE through the label filter as a multiple of the twin's "
        f'label-noise floor, for the run `{repo_path(document["run"])}` (target '
        f'`{document["target"]}`, preprocessing `{document["preprocessing"]}`; bags '
        + ', '.join(f'`{repo_path(bag)}`' for bag in document['bags'])
        + '), recomputed from the bags and the saved models: the floor is the filtered label '
        'minus the filtered noise-free torque on the test rows. 1 means as good as the labels '
        'allow. The best model (lowest mean normalised test RMSE) is in bold. No target is set '
        'here.',
        '',
        *settings,
        *markdown_table(
            ['', *joints],
            [
                [
                    'label-noise floor [N*m]',
                    *(number(x, '.3g') for x in document['label_noise_rms_nm']),
                ],
                [
                    f'best model ({document["best_model"]}) RMSE [N*m]',
                    *(number(x, '.3g') for x in document['best_rmse_through_filter_nm']),
                ],
                ['best per joint', *document['per_joint_best_model']],
                [
                    'per-joint best / floor',
                    *(number(x, '.3g') for x in document['per_joint_best_ratio_to_noise']),
                ],
            ],
        ),
        '',
        'Test RMSE through the filter / floor, per model:',
        '',
        *markdown_table(['model', *joints], rows),
        '',
        *needed_lines(document),
    ]


def needed_lines(document: dict) -> list[str]:
    """Each model's error against the torque the drive needs over the floor, or why absent."""
    if not document['needed_ratio_to_noise_by_model']:
        why = '; '.join(document['needed_torque_notes']) or 'the bags give no planned motion'
        return [f'No error against the torque the drive needs: {why}.']
    return [
        'Test RMSE against the torque the drive needs / floor, per model (the model on the '
        'planned reference, against the noise-free torque at each sample time without the '
        "label's delay, unfiltered):",
        '',
        *markdown_table(
            ['model', *document['joints']],
            [
                [kind, *(number(x, '.3g') for x in ratios)]
                for kind, ratios in document['needed_ratio_to_noise_by_model'].items()
            ],
        ),
    ]


if __name__ == '__main__':
    main()
