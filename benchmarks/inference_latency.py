"""One-sample prediction latency (median, p99) of every model of a run, as JSON.

    python benchmarks/inference_latency.py [--run RUN_DIR] [--calls 1000] [--threads 1]

With ``--run`` the run's models are loaded (and verified) and timed on the test part of its
first training bag. Without it, a quick set of all seven models is trained first (one short twin
recording, two epochs each: latency does not depend on how well a model is trained).
A sequence model (LSTM) is timed on one window, the call the online predictor makes per cycle.

``numpy_median_ms`` / ``numpy_p99_ms`` time the float64 one-sample path the predictor node runs
by default (``sample_predictor``; the LSTM's ``sequence_predictor``, one sample pushed per call)
over the same samples, in the same process and thread settings.

Prints the table on stderr and the JSON document on stdout; writes docs/results/
inference_latency.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from common import (
    DEFAULT_ROBOT,
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    settings_lines,
)

from id_learning.dataset.preprocess import prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.registry import STUDY_MODELS, load_model
from id_learning.predictor import set_openblas_threads
from id_learning.robot import load_robot_config
from id_learning.training.trainer import measure_inference, preprocess_from_dict, read_run


def quick_run(out: Path, robot_path: Path) -> Path:
    from id_learning.training import train_run
    from id_learning.twin import load_twin_config, simulate, write_twin_output

    config = load_twin_config(REPO / 'config/twin_default.yaml')
    config = replace(config, excitation=replace(config.excitation, duration_s=60.0))
    bag = write_twin_output(simulate(config), config, out / 'bag')
    hyper = {kind: {'max_epochs': 2} for kind in STUDY_MODELS if kind != 'rnea_lq'}
    train_run(
        [bag],
        load_robot_config(robot_path),
        'motor',
        STUDY_MODELS,
        out / 'run',
        hyper=hyper,
        progress=False,
        device='cpu',
    )
    return out / 'run'


def numpy_path_latency(
    model: InverseDynamicsModel,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    *,
    calls: int,
    threads: int,
) -> tuple[float, float]:
    """Median and p99 [s] of one call of the model's float64 one-sample path."""
    torch_threads = torch.get_num_threads()
    torch.set_num_threads(threads)  # the LSTM's products run through torch
    set_openblas_threads(threads)
    try:
        return _time_calls(model, q, v, a, calls)
    finally:
        torch.set_num_threads(torch_threads)


def _time_calls(
    model: InverseDynamicsModel, q: np.ndarray, v: np.ndarray, a: np.ndarray, calls: int
) -> tuple[float, float]:
    if model.is_sequence_model:
        streams = model.sequence_predictor()  # type: ignore[attr-defined]
        rows = np.hstack([q, v, a])

        def call(k: int) -> None:
            streams.push(rows[k])
    else:
        predict_one = model.sample_predictor()

        def call(k: int) -> None:
            predict_one(q[k], v[k], a[k])

    for k in range(min(50, len(q))):  # warm-up (and the LSTM's padded start)
        call(k)
    times = []
    for k in range(calls):
        start = time.perf_counter()
        call(k % len(q))
        times.append(time.perf_counter() - start)
    return float(np.median(times)), float(np.percentile(times, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--run', type=Path, help='run folder (default: train a quick set)')
    parser.add_argument('--robot', type=Path, help='robot config (default: the run one)')
    parser.add_argument('--calls', type=int, default=1000, help='timed calls per model')
    parser.add_argument('--threads', type=int, default=1, help='torch threads for the calls')
    add_results_options(parser)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        run_dir = args.run or quick_run(Path(scratch), args.robot or DEFAULT_ROBOT)
        run = read_run(run_dir)
        robot = load_robot_config(args.robot or run['robot_config'])
        bag = Path(run['training_data']['bags'][0]['path'])
        dataset = prepare_dataset(
            load_recording(bag, robot), robot, preprocess_from_dict(run['preprocessing'])
        )
        test = slice(dataset.n_train, None)
        q, v, a = dataset.q[test], dataset.v[test], dataset.a[test]
        results = {}
        for kind in run['kinds']:
            model = load_model(run_dir / 'models' / kind, robot, kind)
            timing = measure_inference(
                model, q, v, a, calls=args.calls, repeats=3, latency_threads=args.threads
            )
            numpy_median, numpy_p99 = numpy_path_latency(
                model, q, v, a, calls=args.calls, threads=args.threads
            )
            results[kind] = {
                'median_ms': 1e3 * timing['latency_single_sample_median_s'],
                'p99_ms': 1e3 * timing['latency_single_sample_p99_s'],
                'numpy_median_ms': 1e3 * numpy_median,
                'numpy_p99_ms': 1e3 * numpy_p99,
                'batched_us_per_sample': 1e6 * timing['inference_seconds_per_sample'],
                'window_samples': timing['latency_window_samples'],
            }
        document = {
            'benchmark': 'inference_latency',
            'run': str(args.run) if args.run else 'quick set (2 epochs, 60 s twin bag)',
            'calls': args.calls,
            'latency_threads': args.threads,
            'batched_threads': torch.get_num_threads(),
            'ipo_period_ms': 1e3 * robot.ipo_period_s,
            'models': results,
        }
    lines = report(document, settings_lines('inference_latency', parser, args))
    finish('inference_latency', document, lines, args)


def report(document: dict, settings: list[str]) -> list[str]:
    """The results page's body: what was timed, then one row per model."""
    header = [
        'model',
        'torch median [ms]',
        'torch p99 [ms]',
        'numpy median [ms]',
        'numpy p99 [ms]',
        'batched [us/sample]',
        'window [samples]',
    ]
    rows = [
        [
            kind,
            number(m['median_ms'], '.3f'),
            number(m['p99_ms'], '.3f'),
            number(m['numpy_median_ms'], '.3f'),
            number(m['numpy_p99_ms'], '.3f'),
            number(m['batched_us_per_sample'], '.2f'),
            m['window_samples'],
        ]
        for kind, m in document['models'].items()
    ]
    return [
        "One-sample prediction time of each model, in process (no DDS): torch is the model's "
        'own one-sample call, numpy the float64 path the predictor node runs by default (the '
        'LSTM: one sample pushed into its window per call); median and p99 of '
        f'{document["calls"]} timed calls per model (torch threads: '
        f"{document['latency_threads']}) on the test part of the run's first bag; batched: "
        'the whole test part in one call, per sample (torch threads: '
        f'{document["batched_threads"]}). Models: {document["run"]}. For scale: the IPO period '
        f"is {document['ipo_period_ms']:g} ms (no target is set here; the node's own is in "
        'predictor_latency).',
        '',
        *settings,
        *markdown_table(header, rows),
    ]


if __name__ == '__main__':
    main()
