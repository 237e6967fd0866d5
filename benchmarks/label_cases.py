"""Both label cases on the twin: motor torques from currents vs measured joint torques, JSON.

    python benchmarks/label_cases.py [--duration 600] [--max-seconds-per-model 60] [--out DIR]

Simulates two recordings with config/twin_default.yaml (same seed, so the same excitation): one
as shipped (motor currents; train on tau_u, target 'motor') and one with joint_torque_sensors
true (train on the measured joint torque, target 'joint'). Trains all seven models on each and
prints both per-joint RMSE tables and whether the study's findings hold, with the rules' numbers.

Prints the tables on stderr and the JSON document on stdout; writes docs/results/label_cases.json
and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from common import (
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    settings_lines,
)

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
    add_results_options(parser)
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
    document = {
        'benchmark': 'label_cases',
        'duration_s': args.duration,
        'max_seconds_per_model': args.max_seconds_per_model,
        'device': args.device,
        'cases': cases,
    }
    lines = report(document, settings_lines('label_cases', parser, args))
    finish('label_cases', document, lines, args)


HOLDS = {True: 'holds', False: 'does NOT hold', None: 'not checked'}
TITLES = {
    'motor': 'Motor torques from currents (target motor)',
    'joint': 'Measured joint torques (target joint)',
}


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: per label case the RMSE table, then the findings on both."""
    duration = document['duration_s']
    lines = [
        'Both label cases on the twin (config/twin_default.yaml, same seed and excitation, '
        + (f'{duration:g} s' if duration else "the config's length")
        + '): one recording as shipped, trained on tau_u from the motor currents (target '
        'motor), and one with joint torque sensors, trained on the measured joint torque '
        '(target joint). Every model is trained on each (at most '
        f'{document["max_seconds_per_model"]:g} s per model, device `{document["device"]}`); '
        "test RMSE per joint from the run's metrics, and whether the study's findings hold on "
        "each, by the report's rules.",
        '',
        *settings,
    ]
    for target, case in document['cases'].items():
        joints = case['joints']
        rows = [
            [kind, *(number(x, '.3g') for x in rmse), case['stopped_by'].get(kind) or '-']
            for kind, rmse in case['rmse_nm'].items()
        ]
        lines += [
            f'{TITLES.get(target, target)}: test RMSE [N*m] (run {case["wall_seconds"]:.0f} s).',
            '',
            *markdown_table(['model', *joints, 'stopped by'], rows, 'l' + 'r' * len(joints) + 'l'),
            '',
        ]
    keys: dict[str, dict[str, Any]] = {}
    for target, case in document['cases'].items():
        for finding in case['findings']:
            keys.setdefault(finding['key'], {'claim': finding['claim']})[target] = finding
    targets = list(document['cases'])
    rows = [
        [key, entry['claim'], *(HOLDS[entry[t]['holds']] if t in entry else '-' for t in targets)]
        for key, entry in keys.items()
    ]
    lines += [
        "The study's findings (no target of this benchmark; the numbers behind each verdict are "
        'below and in the JSON):',
        '',
        *markdown_table(
            ['finding', 'study', *(f'on {t} labels' for t in targets)],
            rows,
            'll' + 'l' * len(targets),
        ),
        '',
    ]
    for key, entry in keys.items():
        for target in targets:
            if target in entry:
                finding = entry[target]
                why = f' Why: {finding["why"]}.' if finding.get('why') else ''
                lines.append(f'- {key}, {target} labels: {finding["evidence"]}.{why}')
    return lines


if __name__ == '__main__':
    main()
