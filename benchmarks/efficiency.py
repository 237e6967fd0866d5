"""Computational efficiency per robot and model kind: fit time, online latency, memory, size.

    python benchmarks/efficiency.py [--robots mabi_max100,panda,ur5] [--models all]
        [--seconds 180] [--max-seconds-per-model 60] [--samples 2000] [--seed 2026]

Per robot config (config/NAME.yaml) a seeded twin recording of ``--seconds`` is made the way
``real_robots.py`` makes its twins (``id-learning simulate``; MABI: config/twin_default.yaml,
Panda and UR5: their twin effects there). Per model kind, in a fresh process of its own:

- the fit through ``train_run`` (the path of ``id-learning train``) with ``--models KIND`` and
  ``--max-seconds-per-model``: the fit's wall time (``train_seconds`` of metrics.json: the
  identification and the diagnosis a kind builds on included) and the whole call's;
- peak memory: the process's peak resident set (``VmHWM``, reset through
  /proc/self/clear_refs just before ``train_run``) over its resident set before the call, so the
  figure holds the dataset, the fit, the scoring and saving. Resident memory rather than
  ``tracemalloc``: torch's tensors are allocated outside what tracemalloc sees, and tracing
  every allocation would slow the fit it measures. A fresh process per fit: no fit reuses heap
  another one freed. Where clear_refs cannot be written, the peak since the worker started
  (``ru_maxrss``) stands in, and the JSON says so;
- the artifact's size on disk [kB] and its parameters: the numbers in its weights file (the
  fitted weights or physical parameters; scalers and reports are in its model.json).

Then, in this process, with torch and numpy's BLAS at ``--threads`` (the predictor node's
``torch_threads``, default 1, set as the node sets it): the predictor core the node calls per
sample (``FeedForwardPredictor.from_artifact`` with the node's default guard settings, warmed
up and the garbage collector frozen as the node does; ``step``, ``prepare_next`` left out as the
node runs it after publishing)
on the recording's last ``--warm-up`` + ``--samples`` controller samples at their IPO stamps:
p50 and p99 of ``step`` [ms] over the ``--samples`` after the warm-up, and of the model's own
one-sample call (``sample_predictor``; the LSTM: one sample pushed into its window).

A kind that cannot be trained on a robot's recording (or a robot whose recording fails) is
listed with why; the others go on. Progress goes to stderr.
Prints the table on stderr and the JSON document on stdout; writes docs/results/efficiency.json
and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import gc
import json
import multiprocessing
import os
import resource
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    add_results_options,
    finish,
    markdown_table,
    number,
    repo_path,
    settings_lines,
)
from real_robots import TWIN_ROBOTS, prepare_twin
from tqdm import tqdm

from id_learning.models.registry import MODEL_KINDS

#: Robot config name (config/NAME.yaml) -> its twin in real_robots.py.
TWINS = {'mabi_max100': 'mabi_twin'} | {
    robot.removesuffix('.yaml'): twin for twin, robot in TWIN_ROBOTS.items()
}
DEFAULT_ROBOTS = ('mabi_max100', 'panda', 'ur5')


# -- the fit, in a process of its own ------------------------------------------------------------
def _status_kb(field: str) -> int | None:
    """A ``Vm*`` line of /proc/self/status [kB], None where there is none."""
    try:
        for line in Path('/proc/self/status').read_text(encoding='ascii').splitlines():
            if line.startswith(f'{field}:'):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    """Reset the kernel's peak resident set (VmHWM) to the current one; whether it could."""
    try:
        Path('/proc/self/clear_refs').write_text('5', encoding='ascii')
    except OSError:
        return False
    return True


@dataclass(frozen=True)
class Fit:
    """One kind to train on one recording (what the fitting process is sent)."""

    bag: Path
    robot_yaml: Path
    target: str
    kind: str
    out: Path
    max_seconds: float | None
    device: str


def fit_kind(fit: Fit) -> dict[str, Any]:
    """Train one kind through ``train_run`` (run in a fresh process); times and memory.

    Returns the fit's and the call's wall time, epochs, how the fit stopped and the memory
    figures [MB], or ``{'skipped': why}`` where the kind could not be trained.
    """
    os.dup2(2, 1)  # what the fit prints goes to stderr: stdout carries the JSON document
    from id_learning.robot import load_robot_config
    from id_learning.training import train_run

    robot = load_robot_config(fit.robot_yaml)
    kind = fit.kind
    before_kb = _status_kb('VmRSS')
    reset = _reset_peak()
    start = time.perf_counter()
    try:
        run = train_run(
            [fit.bag],
            robot,
            fit.target,  # type: ignore[arg-type]
            [kind],
            fit.out,
            max_seconds_per_model=fit.max_seconds,
            progress=False,
            device=fit.device,
        )
    except Exception as err:  # the kind could not be trained on this recording: say why
        return {'skipped': f'{type(err).__name__}: {err}'}
    call_s = time.perf_counter() - start
    peak_kb = _status_kb('VmHWM') if reset else None
    if peak_kb is None:  # the peak since the worker started [kB on Linux]
        peak_kb, reset = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, False
    if kind in run.failures:
        return {'skipped': run.failures[kind]}
    entry = run.metrics['models'][kind]
    history = entry.get('history') or {}
    return {
        'train_seconds': entry['train_seconds'],
        'train_run_seconds': call_s,
        'epochs': history.get('epochs'),
        'stopped_by': history.get('stopped_by'),
        'cut_short': entry.get('cut_short') or [],
        'rss_before_mb': None if before_kb is None else before_kb / 1024,
        'peak_rss_mb': peak_kb / 1024,
        'peak_growth_mb': None if before_kb is None else (peak_kb - before_kb) / 1024,
        'peak_from': 'VmHWM reset before train_run' if reset else 'ru_maxrss of the worker',
        'artifact': str(run.models[kind].folder),
        'preprocessing': json.loads((fit.out / 'run.json').read_text())['preprocessing'],
    }


def fit_in_own_process(fit: Fit) -> dict[str, Any]:
    """``fit_kind`` in a fresh (spawned) process: its memory is the fit's alone."""
    context = multiprocessing.get_context('spawn')
    with ProcessPoolExecutor(1, mp_context=context) as pool:
        result: dict[str, Any] = pool.submit(fit_kind, fit).result()
    return result


# -- the online path ---------------------------------------------------------------------------
def percentiles_ms(seconds: np.ndarray) -> dict[str, float]:
    """p50 and p99 of call times [s] in ms."""
    return {
        'p50_ms': 1e3 * float(np.percentile(seconds, 50)),
        'p99_ms': 1e3 * float(np.percentile(seconds, 99)),
    }


def online_latency(
    artifact: Path, robot: Any, motion: Any, stamps_ns: np.ndarray, *, warm_up: int, samples: int
) -> dict[str, Any]:
    """The predictor core's ``step`` and the model's one-sample call on a stream of samples.

    ``motion`` (q, v, a, each (N, n)) and ``stamps_ns`` (N,) are played in order; where N is
    short of ``warm_up + samples`` they are played again after a gap in the stamps (the core
    starts its history again there, as after a hole in the reference).
    """
    from id_learning.nodes.params import PredictorNodeConfig, guard_config
    from id_learning.predictor import FeedForwardPredictor

    node = PredictorNodeConfig(artifact=str(artifact))
    core = FeedForwardPredictor.from_artifact(
        artifact, robot, guard_config(node, robot), inference='numpy'
    )
    core.warm_up()
    # As the node: what torch and the model left is frozen, so no collection walks it per call.
    gc.collect()
    gc.freeze()
    try:
        step_s, served = _time_steps(core, motion, stamps_ns, warm_up, samples)
        model_s = _time_model(core.model, motion, warm_up, samples)
    finally:
        gc.unfreeze()
    return {
        'step': percentiles_ms(step_s),
        'model': percentiles_ms(model_s),
        'served_share': served / samples,
        'parameters': int(sum(np.asarray(x).size for x in core.model.state().values())),
    }


def _time_steps(
    core: Any, motion: Any, stamps_ns: np.ndarray, warm_up: int, samples: int
) -> tuple[np.ndarray, int]:
    """Seconds of each timed ``step`` (``prepare_next`` untimed, after it, as the node runs it)
    and how many of them served the model's torque."""
    from id_learning.predictor import ReferenceSample

    joints = core.joint_names
    n = len(stamps_ns)
    span = int(stamps_ns[-1] - stamps_ns[0]) + 10**9  # a hole between two passes
    seconds = np.empty(samples)
    served = 0
    for k in range(warm_up + samples):
        row = k % n
        stamp = int(stamps_ns[row]) + (k // n) * span
        sample = ReferenceSample(stamp, joints, motion.q[row], motion.v[row], motion.a[row])
        start = time.perf_counter()
        result = core.step(sample, stamp)
        elapsed = time.perf_counter() - start
        core.prepare_next()
        if k >= warm_up:
            seconds[k - warm_up] = elapsed
            served += result.tau is not None and result.reject is None
    return seconds, served


def _time_model(model: Any, motion: Any, warm_up: int, samples: int) -> np.ndarray:
    """Seconds of each timed one-sample call of the model's numpy path (the LSTM: a push)."""
    if model.is_sequence_model:
        stream = model.sequence_predictor()
        rows = np.hstack([motion.q, motion.v, motion.a])

        def call(row: int) -> None:
            stream.push(rows[row])
    else:
        predict_one = model.sample_predictor()

        def call(row: int) -> None:
            predict_one(motion.q[row], motion.v[row], motion.a[row])

    n = len(motion.q)
    seconds = np.empty(samples)
    for k in range(warm_up + samples):
        start = time.perf_counter()
        call(k % n)
        if k >= warm_up:
            seconds[k - warm_up] = time.perf_counter() - start
    return seconds


def folder_kb(folder: Path) -> float:
    """The files under ``folder`` [kB]."""
    return sum(p.stat().st_size for p in folder.rglob('*') if p.is_file()) / 1024


def stream_of(bag: Path, robot: Any, preprocessing: dict[str, Any], rows: int) -> Any:
    """The last ``rows`` controller samples of a recording, as the run preprocessed it."""
    from id_learning.dataset.preprocess import prepare_dataset
    from id_learning.dataset.recording import load_recording
    from id_learning.training.datasets import preprocess_from_dict

    dataset = prepare_dataset(
        load_recording(bag, robot), robot, preprocess_from_dict(preprocessing)
    )
    tail = slice(max(0, len(dataset.stamps_ns) - rows), None)
    return dataset.controller.take(tail), dataset.stamps_ns[tail]


# -- one robot ---------------------------------------------------------------------------------
def measure_robot(
    name: str, kinds: list[str], args: argparse.Namespace, out: Path, bar: tqdm
) -> dict[str, Any]:
    """Simulate the robot's twin, fit and time every kind; the robot's JSON entry."""
    from id_learning.robot import load_robot_config

    entry: dict[str, Any] = {'twin': TWINS[name], 'models': {}}
    bar.set_postfix_str(f'{name}: simulate')
    out.mkdir(parents=True, exist_ok=True)
    job = prepare_twin(TWINS[name], out, args.seconds, args.seed)
    simulated = job.steps['simulate']
    entry['simulate_seconds'] = simulated['wall_s']
    entry['target'] = job.target
    if simulated['returncode']:
        reason = f'the twin recording failed: {simulated.get("error", "")}'
        entry['models'] = {kind: {'skipped': reason} for kind in kinds}
        bar.update(len(kinds))
        return entry
    robot = load_robot_config(job.robot_yaml)
    entry['robot_config'] = repo_path(job.robot_yaml)
    entry['joints'] = len(robot.joints)
    entry['ipo_period_ms'] = 1e3 * robot.ipo_period_s
    stream = None
    for kind in kinds:
        bar.set_postfix_str(f'{name}: {kind}')
        fit = Fit(
            job.bags[0],
            job.robot_yaml,
            job.target,
            kind,
            out / f'run_{kind}',
            args.max_seconds_per_model,
            args.device,
        )
        fitted = fit_in_own_process(fit)
        if 'skipped' not in fitted:
            artifact = Path(fitted.pop('artifact'))
            preprocessing = fitted.pop('preprocessing')
            if stream is None:
                stream = stream_of(job.bags[0], robot, preprocessing, args.warm_up + args.samples)
                entry['stream_samples'] = len(stream[1])
            fitted['artifact_kb'] = folder_kb(artifact)
            fitted.update(
                online_latency(
                    artifact, robot, *stream, warm_up=args.warm_up, samples=args.samples
                )
            )
        entry['models'][kind] = fitted
        bar.write(f'{name} {kind}: {summary(fitted)}', file=sys.stderr)
        bar.update()
    return entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--robots',
        default=','.join(DEFAULT_ROBOTS),
        help=f'robot configs, comma-separated, of {", ".join(TWINS)}',
    )
    parser.add_argument(
        '--models', default='all', help='model kinds, comma-separated (all: every kind)'
    )
    parser.add_argument(
        '--seconds',
        type=float,
        default=180.0,
        help="length of each twin recording [s] (the MABI's training part must hold about 91 s "
        'for the diagnosis that rnea_effects builds on)',
    )
    parser.add_argument(
        '--max-seconds-per-model', type=float, default=60.0, help='fit budget per kind [s]'
    )
    parser.add_argument('--seed', type=int, default=2026, help="the twins' seed")
    parser.add_argument('--samples', type=int, default=2000, help='timed samples per kind')
    parser.add_argument('--warm-up', type=int, default=200, help='untimed samples before them')
    parser.add_argument(
        '--threads', type=int, default=1, help="torch and BLAS threads (the node's torch_threads)"
    )
    parser.add_argument('--device', default='cpu', help='device of the fits (auto, cpu, cuda)')
    parser.add_argument('--out', type=Path, help='keep recordings and runs here (default: temp)')
    add_results_options(parser)
    args = parser.parse_args()
    robots = [r.strip() for r in args.robots.split(',') if r.strip()]
    unknown = sorted(set(robots) - set(TWINS))
    if unknown or not robots:
        parser.error(f'--robots: unknown {unknown}; known: {list(TWINS)}')
    kinds = (
        list(MODEL_KINDS)
        if args.models == 'all'
        else [k.strip() for k in args.models.split(',') if k.strip()]
    )
    if not kinds or set(kinds) - set(MODEL_KINDS):
        parser.error(f'--models: unknown {sorted(set(kinds) - set(MODEL_KINDS))}')
    if args.samples < 1 or args.warm_up < 0 or args.threads < 1:
        parser.error('--samples and --threads must be at least 1, --warm-up at least 0')

    from id_learning.predictor import configure_inference_threads

    configure_inference_threads(args.threads)  # as the node does, before any torch work
    start = time.perf_counter()
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as scratch:
        out = (args.out or Path(scratch)).resolve()
        with tqdm(total=len(robots) * len(kinds), desc='fits', unit='fit') as bar:
            for name in robots:
                results[name] = measure_robot(name, kinds, args, out / name, bar)
    document = {
        'benchmark': 'efficiency',
        'robots': results,
        'kinds': kinds,
        'twin_seconds': args.seconds,
        'seed': args.seed,
        'max_seconds_per_model': args.max_seconds_per_model,
        'device': args.device,
        'samples': args.samples,
        'warm_up': args.warm_up,
        'latency_threads': args.threads,
        'wall_seconds': time.perf_counter() - start,
    }
    finish(
        'efficiency', document, report(document, settings_lines('efficiency', parser, args)), args
    )


def summary(m: dict[str, Any]) -> str:
    """One line of a kind's figures (or why it was skipped), for the progress log."""
    if 'skipped' in m:
        return f'skipped: {m["skipped"]}'
    return (
        f'fit {m["train_seconds"]:.1f} s ({stopped_by(m)}), train_run '
        f'{m["train_run_seconds"]:.1f} s, step p50/p99 {m["step"]["p50_ms"]:.3f}/'
        f'{m["step"]["p99_ms"]:.3f} ms, peak {number(m["peak_growth_mb"], ".0f")} MB, '
        f'{m["artifact_kb"]:.1f} kB'
    )


def stopped_by(m: dict[str, Any]) -> str:
    """How a fit ended: its loop's reason, else 'time_budget' where a step was cut short."""
    return m['stopped_by'] or ('time_budget' if m['cut_short'] else 'done')


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: what was measured, one row per robot and kind, the skips."""
    rows, notes = [], []
    for robot, entry in document['robots'].items():
        for kind, m in entry['models'].items():
            if 'skipped' in m:
                notes.append(f'- {robot}, `{kind}`: not measured: {m["skipped"]}')
                continue
            if m['served_share'] < 1.0:
                notes.append(
                    f'- {robot}, `{kind}`: the model served {m["served_share"]:.1%} of the '
                    'timed steps (the guards held or refused the others)'
                )
            rows.append([
                robot,
                kind,
                number(m['train_seconds'], '.1f'),
                stopped_by(m),
                number(m['train_run_seconds'], '.1f'),
                number(m['step']['p50_ms'], '.3f'),
                number(m['step']['p99_ms'], '.3f'),
                number(m['model']['p50_ms'], '.3f'),
                number(m['model']['p99_ms'], '.3f'),
                number(m['peak_growth_mb'], '.0f'),
                number(m['artifact_kb'], '.1f'),
                m['parameters'],
            ])  # fmt: skip
    robots = document['robots'].values()
    periods = ', '.join(
        f'{name} {e["ipo_period_ms"]:g} ms'
        for name, e in document['robots'].items()
        if 'ipo_period_ms' in e
    )
    peaks = sorted(
        {m['peak_from'] for e in robots for m in e['models'].values() if 'peak_from' in m}
    )
    header = [
        'robot',
        'kind',
        'fit [s]',
        'stopped by',
        'train_run [s]',
        'step p50 [ms]',
        'step p99 [ms]',
        'model p50 [ms]',
        'model p99 [ms]',
        'peak memory [MB]',
        'artifact [kB]',
        'parameters',
    ]
    return [
        f'Per robot config a seeded twin recording of {document["twin_seconds"]:g} s (seed '
        f'{document["seed"]}, made as `real_robots.py` makes its twins); per model kind, in a '
        'process of its own, the fit through `train_run` (the path of `id-learning train`, '
        f'device `{document["device"]}`, at most {document["max_seconds_per_model"]:g} s per '
        "fit). Fit: metrics.json's `train_seconds` (the identification and the diagnosis a kind "
        'builds on included); train_run: the whole call (dataset, fit, scoring, report, '
        "saving). Peak memory: the process's peak resident memory during `train_run` over its "
        f'resident memory before it ({", ".join(peaks) or "-"}). Then, with '
        f'{document["latency_threads"]} torch/BLAS thread(s) as the predictor node sets them '
        "and the garbage collector frozen as the node freezes it: the node's per-sample call "
        "(step: `FeedForwardPredictor.step` with the node's default guards, numpy inference) "
        "and the model's own one-sample call within it (model), p50 and p99 of "
        f'{document["samples"]} calls after {document["warm_up"]} untimed ones on the '
        "recording's last controller samples at their stamps; no DDS (`predictor_latency.py` "
        f'measures the node over DDS). For scale, the IPO periods: {periods or "-"}. Artifact: '
        'model.json and the weights on disk; parameters: the numbers in the weights file (the '
        'fitted parameters; scalers and reports are in model.json). The whole run took '
        f'{document["wall_seconds"]:.0f} s.',
        '',
        *settings,
        *markdown_table(header, rows, 'llrlrrrrrrrr'),
        *(['', *notes] if notes else []),
    ]


if __name__ == '__main__':
    main()
