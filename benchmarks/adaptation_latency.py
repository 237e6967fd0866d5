"""What online adaptation adds to the predictor's time per sample, with and without it.

    python benchmarks/adaptation_latency.py [--kinds rnea_lq mlp] [--samples 20000]
        [--mode rls|rls_inertia]

The predictor core (``FeedForwardPredictor.step``, the node's hot path without DDS) serves a
smooth reference at the IPO rate, once as fitted and once with adaptation (``--mode``); with
adaptation each sample also gets its measured currents (``AdaptationLoop.measured``: one RLS
update), as the node receives them on the same thread. Reported per kind: median and p99 of the
step alone, and of step plus update, and what adaptation adds to each [ms].
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from common import DEFAULT_ROBOT, emit
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
    emit(
        {
            'benchmark': 'adaptation_latency',
            'mode': args.mode,
            'samples': args.samples,
            'kinds': out,
        }
    )


if __name__ == '__main__':
    main()
