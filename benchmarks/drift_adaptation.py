"""A shift of warm-up drift: the frozen model, the adapting one, and one refitted on the last hour.

    python benchmarks/drift_adaptation.py [--hours 0,1,...,8] [--window 240] [--catch-up 120]
        [--mode rls|rls_inertia]

The twin robot of config/twin_default.yaml with its viscous and Coulomb friction falling by 30 %
over the shift (``warm_scale`` 0.7, ``warm_up_s`` 2 h: 0.705 of the cold friction after 8 h).
- frozen: ``rnea_id`` identified on a recording at the start of the shift;
- adapted: the same model with the predictor's adaptation (``AdaptationLoop``, ``--mode``)
  learning from the measured currents, online, window after window (a priori errors: each
  sample is predicted before it is learnt from). The hours between windows are not simulated:
  the adapter resumes from where the last window left it and gets each window's first
  ``--catch-up`` seconds to catch up; every window is scored on the rest;
- refit: ``rnea_id`` identified on a recording that ends where each window starts (``--fit``
  seconds: the freshest refit the last hour allows).
Each window's tau_u RMSE is against the twin's noise-free tau_u, per joint, on the controller's
reference (the true motion). Prints the table and JSON, and the adapter's update time per sample;
writes docs/results/drift_adaptation.json and .md (not with ``--no-results``;
``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml
from common import (
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    settings_lines,
)

from id_learning.models.registry import load_model
from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.training import train_run
from id_learning.twin import load_twin_config, simulate, write_twin_output

HOUR_S = 3600.0


def twin(shift_start_s: float, seed: int, duration_s: float):
    data = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text())
    for name in ('viscous_friction', 'coulomb_friction'):
        data['effects'][name] |= {'warm_scale': 0.7, 'warm_up_s': 2 * HOUR_S}
    data |= {'seed': seed, 'robot_seed': 2026, 'shift_start_s': shift_start_s}
    path = Path(tempfile.mkdtemp()) / 'twin.yaml'
    data['robot'] = str(REPO / 'config/mabi_max100.yaml')
    path.write_text(yaml.safe_dump(data))
    config = load_twin_config(path)
    return replace(config, excitation=replace(config.excitation, duration_s=duration_s))


def fitted(config, folder: Path):
    result = simulate(config)
    bag = write_twin_output(result, config, folder / 'bag')
    run = train_run([bag], config.robot, 'motor', ['rnea_id'], folder / 'run', progress=False)
    return load_model(run.models['rnea_id'].folder, config.robot, 'rnea_id')


def rmse(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((a - b) ** 2, axis=0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--hours', default='0,1,2,3,4,5,6,7,8')
    parser.add_argument('--window', type=float, default=240.0, help='test window per hour [s]')
    parser.add_argument(
        '--catch-up', type=float, default=120.0, help='unscored start of each window [s]'
    )
    parser.add_argument('--mode', choices=('rls', 'rls_inertia'), default='rls')
    parser.add_argument('--fit', type=float, default=300.0, help='fitting recordings [s]')
    add_results_options(parser)
    args = parser.parse_args()
    hours = [float(h) for h in args.hours.split(',')]
    work = Path(tempfile.mkdtemp())
    robot = twin(0.0, 1, 1.0).robot
    frozen = fitted(twin(0.0, 1, args.fit), work / 'frozen')
    loop = AdaptationLoop.for_robot(
        robot, robot.joints, AdaptationConfig(), inertia=args.mode == 'rls_inertia'
    )
    update_s: list[float] = []
    rows = []
    for hour in hours:
        window = simulate(twin(hour * HOUR_S, 100 + int(hour), args.window))
        q, v, a = window.q_true, window.v_true, window.a_true
        currents = window.recording.current
        model = frozen.predict(q, v, a)
        adapted = np.empty_like(model)
        for k in range(len(q)):  # served on the reference, learnt from the cycle's currents
            adapted[k] = loop.serve(k, (q[k], v[k], a[k]), model[k])
            start = time.perf_counter()
            loop.measured(k, currents[k])
            update_s.append(time.perf_counter() - start)
        start_s = max(0.0, hour * HOUR_S - args.fit)  # the last minutes before the window
        refit = fitted(twin(start_s, 200 + int(hour), args.fit), work / f'refit_{hour:g}')
        # Scored after the catch-up: it stands for the hour between windows, which a
        # continuous run spends tracking the drift.
        half = slice(round(args.catch_up / robot.ipo_period_s), None)
        clean = window.tau_u_clean[half]
        row = {
            'hour': hour,
            'friction_scale': 0.7 + 0.3 * np.exp(-hour / 2.0),
            'frozen_rmse_nm': rmse(model[half], clean).tolist(),
            'adapted_rmse_nm': rmse(adapted[half], clean).tolist(),
            'refit_rmse_nm': rmse(refit.predict(q, v, a)[half], clean).tolist(),
            'theta': (
                loop.adapter.theta if loop.inertia is None else loop.inertia.friction
            ).tolist(),
        }
        rows.append(row)
        print(
            f'hour {hour:g}: friction x{row["friction_scale"]:.3f}; mean RMSE [N*m] frozen '
            f'{np.mean(row["frozen_rmse_nm"]):.2f}, adapted {np.mean(row["adapted_rmse_nm"]):.2f}'
            f', refit {np.mean(row["refit_rmse_nm"]):.2f}',
            flush=True,
        )
    frozen_growth = np.mean(rows[-1]['frozen_rmse_nm']) / np.mean(rows[0]['frozen_rmse_nm'])
    adapted_vs_refit = [
        float(np.mean(r['adapted_rmse_nm']) / np.mean(r['refit_rmse_nm'])) for r in rows
    ]
    document = {
        'benchmark': 'drift_adaptation',
        'hours': rows,
        'frozen_growth': float(frozen_growth),
        'adapted_over_refit': adapted_vs_refit,
        'mode': args.mode,
        'window_s': args.window,
        'catch_up_s': args.catch_up,
        'fit_s': args.fit,
        'adapter': loop.report(robot.joints),
        'update_us': {
            'median': 1e6 * float(np.median(update_s)),
            'p99': 1e6 * float(np.percentile(update_s, 99)),
        },
    }
    lines = report(document, settings_lines('drift_adaptation', parser, args))
    finish('drift_adaptation', document, lines, args)


def report(document: dict, settings: list[str]) -> list[str]:
    """The results page's body: per hour the three models' RMSE, mean over the joints."""
    header = [
        'hour',
        'friction scale',
        'frozen RMSE [N*m]',
        'adapted RMSE [N*m]',
        'refit RMSE [N*m]',
        'adapted / refit',
    ]
    rows = [
        [
            f'{row["hour"]:g}',
            number(row['friction_scale'], '.3f'),
            number(np.mean(row['frozen_rmse_nm']), '.3f'),
            number(np.mean(row['adapted_rmse_nm']), '.3f'),
            number(np.mean(row['refit_rmse_nm']), '.3f'),
            number(ratio, '.2f'),
        ]
        for row, ratio in zip(document['hours'], document['adapted_over_refit'], strict=True)
    ]
    update = document['update_us']
    return [
        'A shift of warm-up drift on the twin robot (config/twin_default.yaml; viscous and '
        'Coulomb friction falling 30 % over the shift): `rnea_id` frozen at the start, the same '
        f'model adapting online (`{document["mode"]}`), and `rnea_id` refitted on the '
        f'{document["fit_s"]:g} s before each window. Each hourly window is '
        f'{document["window_s"]:g} s, its first {document["catch_up_s"]:g} s unscored (the '
        "adapter's catch-up); tau_u RMSE against the twin's noise-free tau_u, mean over the "
        'joints (per joint in the JSON). No target is set here.',
        '',
        *settings,
        *markdown_table(header, rows),
        '',
        f'Frozen model, last hour over first: {document["frozen_growth"]:.2f}x. Adapter update '
        f'per sample: median {update["median"]:.1f} us, p99 {update["p99"]:.1f} us.',
    ]


if __name__ == '__main__':
    main()
