"""Both label cases on the twin: motor torques from currents vs measured joint torques, JSON.

    python benchmarks/label_cases.py [--duration 600] [--max-seconds-per-model 60] [--out DIR]

Simulates two recordings with config/twin_default.yaml (same seed, so the same excitation): one
as shipped (motor currents; train on tau_u, target 'motor') and one with joint_torque_sensors
true (train on the measured joint torque, target 'joint'). Trains all seven models on each and
prints both per-joint RMSE tables and whether the study's findings hold, with the rules' numbers.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from common import REPO, emit

from id_learning.models.registry import STUDY_MODELS
from id_learning.robot import load_robot_config
from id_learning.training import train_run
from id_learning.twin import load_twin_config, simulate, write_twin_output


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--duration', type=float, help='recording length [s] (default: config)')
    parser.add_argument('--max-seconds-per-model', type=float, default=60.0)
    parser.add_argument('--models', default=','.join(STUDY_MODELS))
    parser.add_argument('--device', default='auto')
    parser.add_argument('--out', type=Path, help='keep bags and runs here (default: temp)')
    args = parser.parse_args()
    kinds = [k.strip() for k in args.models.split(',') if k.strip()]
    robot = load_robot_config(REPO / 'config/mabi_max100.yaml')
    cases = {}
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or Path(scratch)
        for target, sensors in (('motor', False), ('joint', True)):
            config = load_twin_config(
                REPO / 'config/twin_default.yaml', {'joint_torque_sensors': sensors}
            )
            if args.duration:
                config = replace(
                    config, excitation=replace(config.excitation, duration_s=args.duration)
                )
            bag = write_twin_output(
                simulate(config), config, out / f'twin_{target}', overwrite=True
            )
            start = time.perf_counter()
            run = train_run(
                [bag],
                robot,
                target,
                kinds,
                out / f'run_{target}',
                max_seconds_per_model=args.max_seconds_per_model,
                progress=False,
                device=args.device,
            )
            cases[target] = {
                'run': str(run.out) if args.out else None,
                'wall_seconds': time.perf_counter() - start,
                'joints': run.metrics['joints'],
                'rmse_nm': {k: e['rmse_nm'] for k, e in run.metrics['models'].items()},
                'rmse_normalised': {
                    k: e['rmse_normalised'] for k, e in run.metrics['models'].items()
                },
                'stopped_by': {
                    k: (e.get('history') or {}).get('stopped_by')
                    for k, e in run.metrics['models'].items()
                },
                'findings': run.metrics['findings'],
            }
    emit(
        {
            'benchmark': 'label_cases',
            'duration_s': args.duration,
            'max_seconds_per_model': args.max_seconds_per_model,
            'cases': cases,
        }
    )


if __name__ == '__main__':
    main()
