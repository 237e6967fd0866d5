"""Best model's test RMSE per joint divided by the twin's label-noise RMSE after filtering, JSON.

    python benchmarks/noise_floor.py [--run out/demo/run]

The run must have been trained on twin bags (their folders hold ground_truth.npz). The noise is
the preprocessed label minus the noise-free label (``tau_u_clean`` or ``tau_joint_clean``) put
through the same zero-phase low-pass, on the test part of each bag. A ratio near 1 means the
model is as good as the labels allow; the best model is the one with the lowest mean normalised
test RMSE in the run's metrics.json (the per-joint best is reported too).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from common import REPO, emit

from id_learning.dataset.preprocess import lowpass, prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.errors import DatasetError
from id_learning.models.registry import load_model
from id_learning.robot import load_robot_config
from id_learning.training.trainer import predict_rows, preprocess_from_dict, read_run
from id_learning.twin import GROUND_TRUTH_ARRAYS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--run', type=Path, default=REPO / 'out/demo/run')
    args = parser.parse_args()
    run = read_run(args.run)
    robot = load_robot_config(run['robot_config'])
    config = preprocess_from_dict(run['preprocessing'])
    metrics = json.loads((args.run / 'metrics.json').read_text())
    kinds = list(metrics['models'])
    models = {kind: load_model(args.run / 'models' / kind, robot, kind) for kind in kinds}
    key = 'tau_u_clean' if config.target == 'motor' else 'tau_joint_clean'
    noise, errors = [], {kind: [] for kind in kinds}
    for entry in run['training_data']['bags']:
        bag = Path(entry['path'])
        if not (bag / GROUND_TRUTH_ARRAYS).is_file():
            raise DatasetError(f'{bag}: no {GROUND_TRUTH_ARRAYS}; the noise floor needs twin bags')
        dataset = prepare_dataset(load_recording(bag, robot), robot, config)
        with np.load(bag / GROUND_TRUTH_ARRAYS) as arrays:
            clean = arrays[key].astype(float)
        if len(clean) != len(dataset.tau):
            raise DatasetError(f'{bag}: ground truth and recording differ in length')
        clean = lowpass(clean, dataset.cutoff_hz, dataset.period_s, dataset.filter_order)
        test = slice(dataset.n_train, None)
        noise.append(dataset.tau[test] - clean[test])
        rows = [(dataset.n_train, len(dataset.q))]
        for kind, model in models.items():
            errors[kind].append(predict_rows(model, dataset, rows) - dataset.tau[test])
    noise_rms = np.sqrt(np.mean(np.concatenate(noise) ** 2, axis=0))
    rmse = {k: np.sqrt(np.mean(np.concatenate(e) ** 2, axis=0)) for k, e in errors.items()}
    best = min(kinds, key=lambda k: metrics['models'][k]['mean_rmse_normalised'])
    per_joint_best = [min(kinds, key=lambda k, j=j: rmse[k][j]) for j in range(robot.n_joints)]
    emit(
        {
            'benchmark': 'noise_floor',
            'run': str(args.run),
            'target': config.target,
            'joints': list(robot.joints),
            'label_noise_rms_nm': noise_rms.tolist(),
            'best_model': best,
            'best_rmse_nm': rmse[best].tolist(),
            'best_ratio_to_noise': (rmse[best] / noise_rms).tolist(),
            'per_joint_best_model': per_joint_best,
            'per_joint_best_ratio_to_noise': [
                float(rmse[k][j] / noise_rms[j]) for j, k in enumerate(per_joint_best)
            ],
            'ratio_to_noise_by_model': {k: (v / noise_rms).tolist() for k, v in rmse.items()},
        }
    )


if __name__ == '__main__':
    main()
