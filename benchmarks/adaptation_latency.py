"""What online adaptation adds to the predictor's time per sample, with and without it.

    python benchmarks/adaptation_latency.py [--kinds rnea_lq mlp] [--samples 20000]
        [--mode rls|rls_inertia]

The predictor core (``FeedForwardPredictor.step``, the node's hot path without DDS) serves a
smooth reference at the IPO rate, once as fitted and once with adaptation (``--mode``); with
adaptation each sample also gets its measured currents (``AdaptationLoop.measured``: one RLS
update), as the node receives them on the same thread. Reported per kind: median and p99 of the
step alone, and of step plus update, and what adaptation adds to each [ms].

Prints one line per kind, then the JSON document; writes docs/results/adaptation_latency.json and
.md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from common import (
    DEFAULT_ROBOT,
    add_results_options,
    finish,
    markdown_table,
    number,
    settings_lines,
)
from predictor_latency import fit_quick_artifacts

from id_learning.predictor import FeedForwardPredictor, GuardConfig, ReferenceSample
from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.robot import load_robot_config


def serve(core: FeedForwardPredictor, n: int, adapt: bool) -> np.ndarray:
    """Seconds per sample: the step, plus the currents' update when adapting."""
    joints = core.joint_names
    t = np.arange(n) * 0.008
    q = 0.3 * np.sin(0.5 * t[:, None] + np.arange(len(joints)))
    v = 0.15 * np.cos(0.5 * t[:, None] + np.arange(len(joints)))
    a = -0.075 * np.sin(0.5 * t[:, None] + np.arange(len(joints)))
    seconds = np.empty(n)
    for k in range(n):
        stamp = 1_000_000_000 + 8_000_000 * k
        sample = ReferenceSample(stamp, joints, q[k], v[k], a[k])
        start = time.perf_counter()
        result = core.step(sample, time.monotonic_ns())
        if adapt and core.adaptation is not None and result.tau is not None:
            core.adaptation.measured(stamp, result.tau / core.adaptation.torque_per_ampere)
        seconds[k] = time.perf_counter() - start
        core.prepare_next()
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--kinds', nargs='+', default=['rnea_lq', 'mlp', 'lstm'])
    parser.add_argument('--samples', type=int, default=20_000)
    parser.add_argument('--mode', choices=('rls', 'rls_inertia'), default='rls')
    add_results_options(parser)
    args = parser.parse_args()
    robot = load_robot_config(DEFAULT_ROBOT)
    folders = fit_quick_artifacts(Path(tempfile.mkdtemp()), DEFAULT_ROBOT, args.kinds)
    out = {}
    for kind, folder in folders.items():
        figures = {}
        for adapt in (False, True):
            core = FeedForwardPredictor.from_artifact(
                folder, robot, GuardConfig(period_s=robot.ipo_period_s, stale_after_cycles=10**6)
            )
            if adapt:
                core.adaptation = AdaptationLoop.for_robot(
                    robot, core.joint_names, AdaptationConfig(), inertia=args.mode == 'rls_inertia'
                )
            core.warm_up()
            seconds = serve(core, args.samples, adapt)[1000:]  # after the first second
            figures[args.mode if adapt else 'off'] = {
                'median_ms': 1e3 * float(np.median(seconds)),
                'p99_ms': 1e3 * float(np.percentile(seconds, 99)),
            }
        on, off = figures[args.mode], figures['off']
        figures['added_median_ms'] = on['median_ms'] - off['median_ms']
        figures['added_p99_ms'] = on['p99_ms'] - off['p99_ms']
        out[kind] = figures
        print(
            f'{kind}: p99 {figures["off"]["p99_ms"]:.3f} ms off, '
            f'{figures[args.mode]["p99_ms"]:.3f} '
            f'ms with {args.mode} (+{figures["added_p99_ms"]:.3f} ms)',
            flush=True,
        )
    document = {
        'benchmark': 'adaptation_latency',
        'mode': args.mode,
        'samples': args.samples,
        'kinds': out,
    }
    lines = report(document, settings_lines('adaptation_latency', parser, args))
    finish('adaptation_latency', document, lines, args)


def report(document: dict, settings: list[str]) -> list[str]:
    """The results page's body: per kind the time per sample without and with adaptation."""
    mode = document['mode']
    header = [
        'kind',
        'off median [ms]',
        'off p99 [ms]',
        f'{mode} median [ms]',
        f'{mode} p99 [ms]',
        'added median [ms]',
        'added p99 [ms]',
    ]
    rows = [
        [
            kind,
            number(f['off']['median_ms'], '.4f'),
            number(f['off']['p99_ms'], '.4f'),
            number(f[mode]['median_ms'], '.4f'),
            number(f[mode]['p99_ms'], '.4f'),
            number(f['added_median_ms'], '+.4f'),
            number(f['added_p99_ms'], '+.4f'),
        ]
        for kind, f in document['kinds'].items()
    ]
    return [
        "What online adaptation adds to the predictor core's time per sample (its hot path "
        'without DDS, `FeedForwardPredictor.step`): a smooth reference served at the IPO rate, '
        f'{document["samples"]} samples per kind, once as fitted (off) and once with adaptation '
        f'`{mode}` (the step plus one RLS update from the measured currents); the first 1000 '
        "samples are left out. Models: one-epoch fits of the study's sizes (time does not "
        'depend on the fit). No target is set here.',
        '',
        *settings,
        *markdown_table(header, rows),
    ]


if __name__ == '__main__':
    main()
