"""Predictor node latency per model at 125 Hz and 1 kHz, over loopback DDS, as JSON.

    python benchmarks/predictor_latency.py [--artifacts DIR] [--kinds mlp lstm ...]
        [--rates 125 1000] [--seconds 8 2] [--executor events] [--inference numpy]

For each model kind and rate a predictor node is started in its own process; this process
publishes one-point JointTrajectory references at the rate (absolute deadlines) and listens to
tau_u. Reported per kind and rate:

- ``node_receive_to_publish_ms``: the node's own figure, to just after tau_u is published (its
  /diagnostics over the phase), from where ``latency_from`` says: the middleware's receive
  timestamp (rclpy's executors) or, with the events executor, which cannot pass that timestamp
  on, the callback's start: that figure leaves out the dispatch (compare ``round_trip_ms``);
- ``round_trip_ms``: from this process's publish to its receipt of tau_u (two DDS hops, two
  executors), per sample;
- ``sent``, ``received``, ``missed`` (no tau_u at all) and ``late`` (round trip > one period).

The node runs with its default input queue (KEEP_LAST 10): a node slower than the rate drops the
oldest samples (missed) instead of building up an ever longer delay.

Each phase starts with ``--warm-up-seconds`` of reference that the figures leave out (reported
apart under ``warm_up``): the first sample a new node receives from this publisher waits
~45-65 ms before its callback starts (the middleware received it within 0.5 ms), and the samples
queued behind it are late too. That is a start-up transient of the connection, not a cycle of a
running feed-forward.

Without ``--artifacts`` a set of all seven kinds with the study's network sizes is fitted for one
epoch on a short synthetic recording: latency does not depend on how well a model is trained.

Prints the table on stderr and the JSON document on stdout; writes docs/results/
predictor_latency.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import os
import struct
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    DEFAULT_ROBOT,
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    settings_lines,
    verdict,
)

STUDY_SIZE_QUICK = {'max_epochs': 1, 'device': 'cpu', 'stride': 16}
#: The target: at this rate the node's p99 receive-to-publish under 1 ms and no cycle missed.
TARGET_RATE_HZ = 125.0
TARGET_P99_MS = 1.0


def fit_quick_artifacts(folder: Path, robot_path: Path, kinds: list[str]) -> dict[str, Path]:
    """One-epoch models of the study's sizes on a 40 s sine recording."""
    sys.path.insert(0, str(REPO / 'test'))
    from support import sine_recording

    from id_learning.dataset import prepare_dataset
    from id_learning.models.data import TrainingData
    from id_learning.models.registry import make_model, save_model
    from id_learning.robot import load_robot_config

    robot = load_robot_config(robot_path)
    data = TrainingData(prepare_dataset(sine_recording(5000), robot), robot)
    out = {}
    for kind in kinds:
        hyper = {} if kind == 'rnea_lq' else STUDY_SIZE_QUICK
        out[kind] = save_model(make_model(kind, robot, **hyper).fit(data), folder / kind)
    return out


def node_environment(domain_id: int) -> dict[str, str]:
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
        PYTHONUNBUFFERED='1',
        PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), env.get('PYTHONPATH')])),
    )
    env.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    return env


class Bench:
    """This process's ROS side: publisher of the reference, subscriber of tau_u and diagnostics."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from rclpy.experimental import EventsExecutor
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        from id_learning.nodes.qos import DIAGNOSTICS_QOS, reference_qos, torque_qos

        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('latency_bench', context=self.context)
        self.publisher = self.node.create_publisher(
            JointTrajectory, '/reference', reference_qos(100)
        )
        self.received: dict[int, int] = {}  # stamp -> receive time [ns, monotonic]
        self.diagnostics: dict[str, str] = {}
        # Raw bytes and the C++ events executor: this process must not be the bottleneck at
        # 1 kHz. The stamp is read straight from the CDR (after the 4-byte encapsulation).
        self.node.create_subscription(JointState, '/tau_u', self._on_tau, torque_qos(), raw=True)
        self.node.create_subscription(
            DiagnosticArray, '/diagnostics', self._on_diagnostics, DIAGNOSTICS_QOS
        )
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_tau(self, data: bytes) -> None:
        now = time.monotonic_ns()
        sec, nanosec = struct.unpack_from('<iI', data, 4)
        self.received[sec * 1_000_000_000 + nanosec] = now

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.startswith('id_learning/predictor'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def wait(self, condition, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():
                return True
            time.sleep(0.01)
        return condition()

    def close(self) -> None:
        from id_learning.nodes.runtime import close_spun_node

        close_spun_node(self.node, self.executor, self._thread, self._stop)


def run_phase(
    bench: Bench, rate_hz: float, seconds: float, robot, warm_up_seconds: float = 0.0
) -> dict[str, Any]:
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    warm_up = round(rate_hz * warm_up_seconds)
    count = round(rate_hz * seconds)
    period_ns = round(1e9 / rate_hz)
    t = np.arange(warm_up + count) / rate_hz
    q = 0.3 * np.sin(2 * np.pi * 0.2 * t[:, None] + np.arange(robot.n_joints))
    v = np.gradient(q, 1 / rate_hz, axis=0)
    a = np.gradient(v, 1 / rate_hz, axis=0)
    messages = []
    for k in range(len(t)):
        msg = JointTrajectory(joint_names=list(robot.joints))
        msg.points = [
            JointTrajectoryPoint(
                positions=q[k].tolist(), velocities=v[k].tolist(), accelerations=a[k].tolist()
            )
        ]
        messages.append(msg)
    bench.received.clear()
    sent: dict[int, int] = {}
    warm_up_sent: dict[int, int] = {}
    start = time.monotonic_ns() + 50_000_000
    wall_offset = time.time_ns() - time.monotonic_ns()
    for k, msg in enumerate(messages):
        deadline = start + k * period_ns
        delay = deadline - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay * 1e-9)
        now = time.monotonic_ns()
        stamp = now + wall_offset  # wall-clock stamps, strictly increasing
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
        bench.publisher.publish(msg)
        (sent if k >= warm_up else warm_up_sent)[stamp] = now
    bench.wait(lambda: sum(s in bench.received for s in sent) >= count, 10.0)
    # The node's diagnostics cover the phase (its window holds the last `count` samples) once
    # they count every sample.
    bench.wait(lambda: int(bench.diagnostics.get('published', 0)) >= warm_up + count, 5.0)
    round_trip = np.array(
        [(bench.received[s] - t0) * 1e-6 for s, t0 in sent.items() if s in bench.received]
    )
    warm_up_trip = [
        (bench.received[s] - t0) * 1e-6 for s, t0 in warm_up_sent.items() if s in bench.received
    ]
    diag = bench.diagnostics
    return {
        'rate_hz': rate_hz,
        'sent': count,
        'received': len(round_trip),
        'missed': count - len(round_trip),
        'late': int(np.sum(round_trip > period_ns * 1e-6)),
        'latency_from': diag.get('latency_from'),
        'node_receive_to_publish_ms': {
            'median': float(diag.get('latency_median_ms', 'nan')),
            'p99': float(diag.get('latency_p99_ms', 'nan')),
            'max': float(diag.get('latency_max_ms', 'nan')),
            'samples': int(diag.get('latency_samples', 0)),
        },
        'node_compute_ms': {
            'median': float(diag.get('compute_median_ms', 'nan')),
            'p99': float(diag.get('compute_p99_ms', 'nan')),
        },
        'round_trip_ms': {
            'median': float(np.median(round_trip)) if len(round_trip) else None,
            'p99': float(np.percentile(round_trip, 99)) if len(round_trip) else None,
            'max': float(round_trip.max()) if len(round_trip) else None,
        },
        'node_rejected': int(diag.get('rejected', 0)),
        'warm_up': {
            'samples': warm_up,
            'received': len(warm_up_trip),
            'first_round_trip_ms': warm_up_trip[0] if warm_up_trip else None,
            'max_round_trip_ms': max(warm_up_trip) if warm_up_trip else None,
        },
    }


def main() -> None:
    from id_learning.models.registry import STUDY_MODELS
    from id_learning.robot import load_robot_config

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--artifacts', type=Path, help='folder with one artifact per kind')
    parser.add_argument('--robot', type=Path, default=DEFAULT_ROBOT)
    parser.add_argument('--kinds', nargs='+', default=list(STUDY_MODELS))
    parser.add_argument('--rates', nargs='+', type=float, default=[125.0, 1000.0])
    parser.add_argument('--seconds', nargs='+', type=float, default=[8.0, 2.0])
    parser.add_argument('--executor', default='events', choices=['events', 'single_threaded'])
    parser.add_argument('--inference', default='numpy', choices=['numpy', 'torch'])
    parser.add_argument(
        '--warm-up-seconds',
        type=float,
        default=0.5,
        help='reference sent before each measured phase and left out of its figures [s]',
    )
    parser.add_argument('--domain', type=int, default=int(time.time()) % 100 + 120)
    add_results_options(parser)
    args = parser.parse_args()
    robot = load_robot_config(args.robot)
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as scratch:
        if args.artifacts:
            # Absolute: the node processes start elsewhere than this process's folder.
            artifacts = {kind: args.artifacts.resolve() / kind for kind in args.kinds}
        else:
            artifacts = fit_quick_artifacts(Path(scratch), args.robot, args.kinds)
        bench = Bench(args.domain)
        try:
            for kind in args.kinds:
                results[kind] = []
                for rate, seconds in zip(args.rates, args.seconds, strict=True):
                    results[kind].append(
                        measure(
                            bench,
                            artifacts[kind],
                            args,
                            robot,
                            rate=rate,
                            seconds=seconds,
                            scratch=scratch,
                        )
                    )
                    print(kind, results[kind][-1], file=sys.stderr)
        finally:
            bench.close()
    document = {
        'benchmark': 'predictor_latency',
        'executor': args.executor,
        'inference': args.inference,
        'warm_up_seconds': args.warm_up_seconds,
        'artifacts': str(args.artifacts) if args.artifacts else 'quick set (one epoch)',
        'target': 'p99 receive-to-publish < 1 ms at 125 Hz, no missed cycle',
        'results': results,
    }
    lines = report(document, settings_lines('predictor_latency', parser, args))
    finish('predictor_latency', document, lines, args)


def meets_target(phase: dict[str, Any]) -> bool | None:
    """At the target's rate: p99 receive-to-publish under 1 ms, nothing missed; else None."""
    if phase['rate_hz'] != TARGET_RATE_HZ:
        return None
    p99 = phase['node_receive_to_publish_ms']['p99']
    return bool(p99 < TARGET_P99_MS) and phase['missed'] == 0


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: what was measured, then one row per kind and rate."""
    froms = sorted({str(p['latency_from']) for ps in document['results'].values() for p in ps})
    lines = [
        'Latency of the predictor node per model kind over loopback DDS: this process publishes '
        'one-point JointTrajectory references at each rate (absolute deadlines) to a predictor '
        'node in its own process and listens to its tau_u. Executor '
        f'`{document["executor"]}`, inference `{document["inference"]}`, models: '
        f'{document["artifacts"]}; the first {document["warm_up_seconds"]:g} s of each phase '
        "are a warm-up outside the figures. Receive-to-publish is the node's own figure "
        f'(from {", ".join(froms)} to just after tau_u is published); the round trip is this '
        "process's publish to its receipt of tau_u (two DDS hops). Missed: no tau_u at all; "
        'late: round trip over one period.',
        '',
        *settings,
        f'Target: at {TARGET_RATE_HZ:g} Hz a p99 receive-to-publish under {TARGET_P99_MS:g} ms '
        'and no missed cycle (other rates are not judged).',
        '',
    ]
    rows = []
    for kind, phases in document['results'].items():
        for phase in phases:
            node, trip = phase['node_receive_to_publish_ms'], phase['round_trip_ms']
            rows.append(
                [
                    kind,
                    f'{phase["rate_hz"]:g}',
                    phase['sent'],
                    phase['missed'],
                    phase['late'],
                    number(node['median'], '.3f'),
                    number(node['p99'], '.3f'),
                    number(node['max'], '.3f'),
                    number(phase['node_compute_ms']['p99'], '.3f'),
                    number(trip['median'], '.3f'),
                    number(trip['p99'], '.3f'),
                    verdict(meets_target(phase)),
                ]
            )
    header = [
        'kind',
        'rate [Hz]',
        'sent',
        'missed',
        'late',
        'receive-to-publish median [ms]',
        'p99 [ms]',
        'max [ms]',
        'compute p99 [ms]',
        'round trip median [ms]',
        'round trip p99 [ms]',
        'target',
    ]
    judged = [meets_target(phase) for phases in document['results'].values() for phase in phases]
    judged = [ok for ok in judged if ok is not None]
    summary = (
        f'Target met in {sum(judged)} of {len(judged)} kinds at {TARGET_RATE_HZ:g} Hz.'
        if judged
        else f'No phase at {TARGET_RATE_HZ:g} Hz: the target was not judged.'
    )
    return [*lines, *markdown_table(header, rows, 'l' + 'r' * 10 + 'l'), '', summary]


def measure(
    bench: Bench, artifact: Path, args, robot, *, rate: float, seconds: float, scratch: str
):
    count = round(rate * seconds)
    from id_learning.nodes.process import NodeProcess

    parameters = {
        'artifact': artifact,
        'input_topic': '/reference',
        'latency_window': count,  # the measured phase, after the warm-up
        'diagnostics_period_s': 0.2,
        'executor': args.executor,
        'inference': args.inference,
        'stale_after_cycles': 1000,
    }
    log = Path(scratch) / f'predictor_{artifact.name}_{rate:g}.log'
    node = NodeProcess('predictor', parameters, log, node_environment(args.domain))
    try:
        connected = bench.wait(
            lambda: (
                bench.publisher.get_subscription_count() >= 1
                and bench.node.count_publishers('/tau_u') >= 1
            ),
            120.0,
        )
        if not connected:
            raise RuntimeError(f'predictor did not connect: {node.log()[-2000:]}')
        bench.diagnostics = {}
        return run_phase(bench, rate, seconds, robot, args.warm_up_seconds)
    finally:
        node.stop(30)


if __name__ == '__main__':
    main()
