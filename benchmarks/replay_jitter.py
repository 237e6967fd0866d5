"""Replay: publish-time jitter against the 8 ms IPO grid, median and p99, as JSON.

    python benchmarks/replay_jitter.py [--bag bags/default] [--seconds 20] [--rate 1.0]

A replay node plays ``--seconds`` of the bag (with its /clock and JointTrajectory reference) in
its own process. Reported:

- ``node_lateness_ms``: the replay's own figure, each cycle's publish time minus its absolute
  deadline (its final /diagnostics);
- ``arrival_ms``: in this process, each /joint_states arrival minus the ideal grid
  ``t_first + k * period / rate`` (DDS and this process's executor included), after removing the
  median offset, as absolute values; and the arrival-to-arrival interval minus the period.

Prints the table on stderr and the JSON document on stdout; writes docs/results/
replay_jitter.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere), only when
the replay finished.
"""

from __future__ import annotations

import argparse
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    DEFAULT_BAG,
    REPO,
    add_results_options,
    emit,
    markdown_table,
    number,
    publish_results,
    repo_path,
    settings_lines,
)

from id_learning.bag import bag_info


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


def summary_ms(values_ns: np.ndarray) -> dict[str, float]:
    values = np.abs(values_ns) * 1e-6
    return {
        'median': float(np.median(values)),
        'p99': float(np.percentile(values, 99)),
        'max': float(values.max()),
    }


def main() -> None:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from sensor_msgs.msg import JointState

    from id_learning.nodes.qos import DIAGNOSTICS_QOS, sensor_qos
    from id_learning.nodes.runtime import close_spun_node

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bag', type=Path, default=DEFAULT_BAG)
    parser.add_argument('--seconds', type=float, default=20.0)
    parser.add_argument('--rate', type=float, default=1.0)
    parser.add_argument('--executor', default='single_threaded')
    parser.add_argument('--domain', type=int, default=int(time.time()) % 100 + 120)
    add_results_options(parser)
    args = parser.parse_args()

    context = Context()
    rclpy.init(context=context, domain_id=args.domain)
    node = rclpy.create_node('jitter_bench', context=context)
    arrivals: list[tuple[int, int]] = []  # (stamp [ns], arrival [ns, monotonic])
    diagnostics: dict[str, str] = {}

    def on_state(data: bytes) -> None:
        now = time.monotonic_ns()
        sec, nanosec = struct.unpack_from('<iI', data, 4)
        arrivals.append((sec * 1_000_000_000 + nanosec, now))

    def on_diagnostics(msg: Any) -> None:
        for status in msg.status:
            if status.name.startswith('id_learning/replay'):
                diagnostics.update({kv.key: kv.value for kv in status.values})

    node.create_subscription(JointState, '/joint_states', on_state, sensor_qos(1000), raw=True)
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, DIAGNOSTICS_QOS)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    process = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'id_learning.nodes.replay',
            '--ros-args',
            '-p',
            f'bag:={args.bag.resolve()}',
            '-p',
            f'duration_s:={args.seconds}',
            '-p',
            f'rate:={args.rate}',
            '-p',
            'wait_for_subscribers:=1',
            '-p',
            f'executor:={args.executor}',
            '-p',
            'diagnostics_period_s:=0.5',
        ],
        env=node_environment(args.domain),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    log, _ = process.communicate(timeout=args.seconds / args.rate + 300)
    deadline = time.monotonic() + 5
    while diagnostics.get('state') != 'finished' and time.monotonic() < deadline:
        time.sleep(0.05)
    close_spun_node(node, executor, spinner, stop)
    if process.returncode != 0 or not arrivals:
        raise SystemExit(f'replay failed (exit {process.returncode}):\n{log[-3000:]}')

    period_ns = 8_000_000 / args.rate
    stamps = np.array([s for s, _ in arrivals], dtype=np.int64)
    arrived = np.array([t for _, t in arrivals], dtype=np.int64)
    ideal = arrived[0] + (stamps - stamps[0]) / args.rate
    offset = arrived - ideal
    offset -= np.median(offset)
    document = {
        'benchmark': 'replay_jitter',
        'bag': str(args.bag),
        'bag_topics': {t.name: t.count for t in bag_info(args.bag).topics},
        'rate': args.rate,
        'cycles': int(diagnostics.get('cycles_published', 0)),
        'late_cycles_over_one_period': int(diagnostics.get('late_cycles', 0)),
        'node_lateness_ms': {
            'median': float(diagnostics.get('lateness_median_ms', 'nan')),
            'p99': float(diagnostics.get('lateness_p99_ms', 'nan')),
            'max': float(diagnostics.get('lateness_max_ms', 'nan')),
        },
        'arrival_vs_grid_ms': summary_ms(offset),
        'arrival_interval_error_ms': summary_ms(np.diff(arrived) - np.diff(stamps) / args.rate),
        'received_joint_states': len(arrivals),
        'period_ms': period_ns * 1e-6,
        'seconds': args.seconds,
        'executor': args.executor,
    }
    lines = report(document, settings_lines('replay_jitter', parser, args))
    print('\n'.join(lines), file=sys.stderr)
    publish_results('replay_jitter', document, lines, args)
    emit(document)


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: the replay's lateness and the arrivals against the grid."""
    header = ['figure', 'median [ms]', 'p99 [ms]', 'max [ms]']
    rows = [
        [title, *(number(document[key][s], '.3f') for s in ('median', 'p99', 'max'))]
        for key, title in (
            ('node_lateness_ms', 'replay lateness (publish minus deadline, its own figure)'),
            ('arrival_vs_grid_ms', '/joint_states arrival vs the ideal grid (abs.)'),
            ('arrival_interval_error_ms', 'arrival interval minus the period (abs.)'),
        )
    ]
    return [
        f'Replay jitter: a replay node in its own process plays {document["seconds"]:g} s of '
        f'`{repo_path(document["bag"])}` at rate {document["rate"]:g} (executor '
        f'`{document["executor"]}`, period {document["period_ms"]:g} ms); this process '
        'receives its /joint_states over loopback DDS. Arrivals are compared with the ideal '
        'grid after removing their median offset.',
        '',
        *settings,
        *markdown_table(header, rows),
        '',
        f'Cycles published: {document["cycles"]}; later than one period: '
        f'{document["late_cycles_over_one_period"]}; /joint_states received here: '
        f'{document["received_joint_states"]}. No target is set for the jitter.',
    ]


if __name__ == '__main__':
    main()
