"""Identification on fresh twin robots: its time, and how often the base parameters' intervals
hold the truth.

    python benchmarks/identification.py [--seeds 71,72,73] [--duration 600]

Per seed: simulates config/twin_default.yaml (every hidden effect: payload, balancer, link
errors, friction, torque-constant scales, delay), identifies the rigid body and drives on the
training part (``physics.identification``, the default settings of ``rnea_id``) and compares
with the twin's truth: the share of base parameters whose 95 % interval holds the true value
(the twin's links, its payload folded into the carrying body), torque-constant scales, rotor
inertias and the delay. Prints a table and ends with one JSON line; writes docs/results/
identification.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
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
    share,
)

from id_learning.dataset.preprocess import prepare_dataset
from id_learning.physics import RigidBodyDynamics
from id_learning.physics.base_parameters import base_parameters
from id_learning.physics.identification import identify
from id_learning.robot import load_robot_config
from id_learning.twin import load_twin_config, simulate


def true_parameters(parameters: dict[str, Any]) -> np.ndarray:
    """The twin's inertial parameters, its payload already in the carrying body."""
    return np.asarray(parameters['true']['inertial_parameters'], dtype=float)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', default='71,72,73')
    parser.add_argument('--duration', type=float, default=600.0, help='recording length [s]')
    add_results_options(parser)
    args = parser.parse_args()
    robot = load_robot_config(DEFAULT_ROBOT)
    base = base_parameters(RigidBodyDynamics.from_config(robot), robot.limits)
    runs = []
    for seed in (int(s) for s in args.seeds.split(',')):
        config = load_twin_config(REPO / 'config/twin_default.yaml', {'seed': seed})
        config = replace(config, excitation=replace(config.excitation, duration_s=args.duration))
        result = simulate(config)
        dataset = prepare_dataset(result.recording, robot)
        began = time.perf_counter()
        physics = identify(dataset, robot)
        seconds = time.perf_counter() - began
        truth = base.matrix @ true_parameters(result.parameters)
        entries = physics.report['base_parameters']
        inside = [e['ci95'][0] <= t <= e['ci95'][1] for e, t in zip(entries, truth, strict=True)]
        effects = result.parameters['effects']
        runs.append(
            {
                'seed': seed,
                'seconds': seconds,
                'training_samples': int(dataset.n_train),
                'condition_number': physics.report['condition_number'],
                'base_coverage': float(np.mean(inside)),
                'base_identified': int(sum(e['identified'] for e in entries)),
                'base_count': len(entries),
                'torque_constant_scale': (1.0 / (1.0 + physics.gain)).tolist(),
                'torque_constant_scale_true': effects['torque_constant_scale']['scale'],
                'rotor_inertia': physics.rotor.tolist(),
                'rotor_inertia_true': result.parameters['true']['rotor_inertia_motor_side_kgm2'],
                'delay_s': physics.delay_s,
                'delay_s_true': result.parameters['true']['signal_delay_s'],
            }
        )
        r = runs[-1]
        print(
            f'seed {seed}: {r["seconds"]:.1f} s for {r["training_samples"]} samples; '
            f'base parameters: {r["base_coverage"]:.0%} of {r["base_count"]} intervals hold the '
            f'truth, {r["base_identified"]} identified by the data, condition '
            f'{r["condition_number"]:.3g}; delay {1e3 * r["delay_s"]:.2f} ms '
            f'(true {1e3 * r["delay_s_true"]:.2f}); kt scale '
            f'{np.round(r["torque_constant_scale"], 3).tolist()} '
            f'(true {r["torque_constant_scale_true"]})',
            flush=True,
        )
    document = {'benchmark': 'identification', 'duration_s': args.duration, 'runs': runs}
    lines = report(document, settings_lines('identification', parser, args))
    print('\n'.join(lines))
    publish_results('identification', document, lines, args)
    print(json.dumps({**document, 'environment': environment()}))


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: one row per seed against the twin's truth."""
    rows = []
    for r in document['runs']:
        scale = np.asarray(r['torque_constant_scale'])
        scale_true = np.asarray(r['torque_constant_scale_true'])
        rotor = np.asarray(r['rotor_inertia'])
        rotor_true = np.asarray(r['rotor_inertia_true'])
        rows.append(
            [
                r['seed'],
                r['training_samples'],
                number(r['seconds'], '.1f'),
                number(r['condition_number'], '.3g'),
                f'{share(r["base_coverage"])} of {r["base_count"]}',
                r['base_identified'],
                number(1e3 * r['delay_s'], '.2f'),
                number(1e3 * r['delay_s_true'], '.2f'),
                number(100 * np.max(np.abs(scale / scale_true - 1)), '.1f'),
                number(100 * np.max(np.abs(rotor / rotor_true - 1)), '.0f'),
            ]
        )
    return [
        "The identification (`rnea_id`'s default settings) on fresh twin robots of "
        'config/twin_default.yaml, every hidden effect on (payload, balancer, link errors, '
        'friction, torque-constant scales, delay): per seed a '
        f'{document["duration_s"]:g} s recording, identified on its training part, compared '
        "with the twin's truth. Coverage: the share of base parameters whose 95 % interval "
        'holds the true value (the payload folded into its carrying body; near 95 % means '
        'honest intervals); identified: base parameters the data determine. Time: wall time of '
        'the identification alone. No target is set here (fit_cost times it against its '
        'budget).',
        '',
        *settings,
        *markdown_table(
            [
                'seed',
                'training samples',
                'time [s]',
                'condition number',
                'base intervals holding the truth',
                'identified',
                'delay [ms]',
                'true delay [ms]',
                'torque-constant scale, worst error [%]',
                'rotor inertia, worst error [%]',
            ],
            rows,
        ),
    ]


if __name__ == '__main__':
    main()
