"""Recorder: highest sustained zero-loss rate for the two contract topics, and CPU at 125 Hz.

    python benchmarks/recorder_throughput.py [--rates 125 500 1000 2000 3000 4000]
        [--seconds 5] [--executor single_threaded]

For each rate (per topic) a recorder node is started in its own process; this process publishes
6-joint JointStates on /joint_states and /motor_currents at that rate for ``--seconds`` (absolute
deadlines, catching up in bursts when late), waits until the recorder's /diagnostics report every
message or stop changing, stops it with SIGINT and counts the messages in the finished bag.
Zero loss means every sent message is in the bag. The recorder's CPU use is its user + system time
over the streaming span (from /proc), in percent of one core. The sweep stops at the first rate
with a loss; the highest zero-loss rate is reported.

Prints the table on stderr and the JSON document on stdout; writes docs/results/
recorder_throughput.json and .md (not with ``--no-results``; ``--results-folder`` elsewhere).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from common import (
    REPO,
    add_results_options,
    finish,
    markdown_table,
    number,
    settings_lines,
    verdict,
)

TOPICS = ('/joint_states', '/motor_currents')
#: The target: every message kept at this rate per topic.
TARGET_HZ = 2000.0


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


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process [s] (Linux /proc)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class Publisher:
    """This process's publishers and the recorder's diagnostics."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState

        from id_learning.nodes.qos import DIAGNOSTICS_QOS, sensor_qos

        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('throughput_bench', context=self.context)
        self.publishers = {
            topic: self.node.create_publisher(JointState, topic, sensor_qos(1000))
            for topic in TOPICS
        }
        self.diagnostics: dict[str, str] = {}
        self.node.create_subscription(
            DiagnosticArray, '/diagnostics', self._on_diagnostics, DIAGNOSTICS_QOS
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name.startswith('id_learning/recorder'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def stream(self, rate_hz: float, seconds: float) -> int:
        """Publish both topics at the rate; returns the messages sent per topic."""
        from id_learning.nodes.msg_conversions import joint_state_message

        names = [f'joint_{i}' for i in range(1, 7)]
        count = round(rate_hz * seconds)
        period_ns = round(1e9 / rate_hz)
        start = time.monotonic_ns() + 20_000_000
        values = [0.1 * i for i in range(6)]
        for k in range(count):
            delay = start + k * period_ns - time.monotonic_ns()
            if delay > 0:
                time.sleep(delay * 1e-9)
            msg = joint_state_message(k, names, position=values, velocity=values, effort=values)
            for publisher in self.publishers.values():
                publisher.publish(msg)
        return count

    def close(self) -> None:
        from id_learning.nodes.runtime import close_spun_node

        close_spun_node(self.node, self.executor, self._thread, self._stop)


def measure(bench: Publisher, rate: float, args, scratch: Path) -> dict[str, Any]:
    from id_learning.bag import bag_info
    from id_learning.nodes.process import NodeProcess

    bag = scratch / f'bag_{rate:g}'
    log = scratch / f'recorder_{rate:g}.log'
    parameters = {'output': bag, 'executor': args.executor, 'diagnostics_period_s': 0.2}
    node = NodeProcess('recorder', parameters, log, node_environment(args.domain))
    process = node.process
    try:
        deadline = time.monotonic() + 120
        while not all(p.get_subscription_count() for p in bench.publishers.values()):
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError(f'recorder did not subscribe: {node.log()[-2000:]}')
            time.sleep(0.01)
        bench.diagnostics = {}
        cpu_before, wall_before = cpu_seconds(process.pid), time.monotonic()
        sent = bench.stream(rate, args.seconds)
        streamed_s = time.monotonic() - wall_before
        cpu = cpu_seconds(process.pid) - cpu_before
        # Let the recorder drain its queue: until it has everything or stops progressing.
        last, still = -1, 0
        while still < 10:
            written = int(bench.diagnostics.get('written', 0))
            if written >= 2 * sent:
                break
            still = still + 1 if written == last else 0
            last = written
            time.sleep(0.2)
    finally:
        node.stop(60)
    counts = {t.name: t.count for t in bag_info(bag).topics}
    lost = {topic: sent - counts.get(topic, 0) for topic in TOPICS}
    return {
        'rate_hz_per_topic': rate,
        'sent_per_topic': sent,
        'in_bag': counts,
        'lost': lost,
        'zero_loss': not any(lost.values()),
        'recorder_dropped_reported': int(bench.diagnostics.get('dropped', 0)),
        'publish_span_s': streamed_s,
        'achieved_rate_hz': sent / streamed_s,
        'recorder_cpu_percent_of_one_core': 100.0 * cpu / streamed_s,
        'exit_status': process.returncode,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        '--rates', nargs='+', type=float, default=[125.0, 500.0, 1000.0, 2000.0, 3000.0, 4000.0]
    )
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--executor', default='single_threaded')
    parser.add_argument('--domain', type=int, default=int(time.time()) % 100 + 120)
    add_results_options(parser)
    args = parser.parse_args()
    steps = []
    bench = Publisher(args.domain)
    try:
        with tempfile.TemporaryDirectory() as scratch:
            for rate in args.rates:
                steps.append(measure(bench, rate, args, Path(scratch)))
                print(steps[-1], file=sys.stderr)
                if not steps[-1]['zero_loss']:
                    break
    finally:
        bench.close()
    zero_loss = [s['rate_hz_per_topic'] for s in steps if s['zero_loss']]
    at_125 = next((s for s in steps if s['rate_hz_per_topic'] == 125.0), None)
    document = {
        'benchmark': 'recorder_throughput',
        'executor': args.executor,
        'seconds_per_rate': args.seconds,
        'target': '>= 2000 Hz per topic without loss',
        'highest_zero_loss_rate_hz_per_topic': max(zero_loss) if zero_loss else None,
        'cpu_percent_of_one_core_at_125_hz': at_125['recorder_cpu_percent_of_one_core']
        if at_125
        else None,
        'steps': steps,
    }
    lines = report(document, settings_lines('recorder_throughput', parser, args))
    finish('recorder_throughput', document, lines, args)


def meets_target(document: dict[str, Any]) -> bool | None:
    """Zero loss at 2000 Hz or above: True; a loss below it: False; neither reached: None."""
    highest = document['highest_zero_loss_rate_hz_per_topic']
    if highest is not None and highest >= TARGET_HZ:
        return True
    if any(not step['zero_loss'] for step in document['steps']):
        return False
    return None


def report(document: dict[str, Any], settings: list[str]) -> list[str]:
    """The results page's body: the sweep, one row per rate, and the verdict."""
    header = [
        'rate per topic [Hz]',
        'sent per topic',
        *(f'in bag {topic}' for topic in TOPICS),
        'lost (both topics)',
        'achieved rate [Hz]',
        'recorder CPU [% of one core]',
        'zero loss',
    ]
    rows = [
        [
            f'{step["rate_hz_per_topic"]:g}',
            step['sent_per_topic'],
            *(step['in_bag'].get(topic, 0) for topic in TOPICS),
            sum(step['lost'].values()),
            number(step['achieved_rate_hz'], '.0f'),
            number(step['recorder_cpu_percent_of_one_core'], '.1f'),
            'yes' if step['zero_loss'] else 'no',
        ]
        for step in document['steps']
    ]
    highest = document['highest_zero_loss_rate_hz_per_topic']
    cpu = document['cpu_percent_of_one_core_at_125_hz']
    passed = meets_target(document)
    tried = max((step['rate_hz_per_topic'] for step in document['steps']), default=0.0)
    judged = (
        verdict(passed)
        if passed is not None
        else f'not judged (no loss up to {tried:g} Hz, the highest rate tried)'
    )
    cpu_text = f'{cpu:.1f} % of one core' if cpu is not None else 'not measured (no 125 Hz step)'
    return [
        'Recorder throughput: this process publishes 6-joint JointStates on '
        f'{" and ".join(TOPICS)} at each rate per topic for {document["seconds_per_rate"]:g} s '
        f'to a recorder node (executor `{document["executor"]}`) in its own process, stops it '
        'with SIGINT and counts the messages in its bag; the sweep stops at the first rate '
        "with a loss. CPU: the recorder's user + system time over the streaming span.",
        '',
        *settings,
        *markdown_table(header, rows, 'r' * (len(header) - 1) + 'l'),
        '',
        f'Highest rate without loss: {number(highest, "g")} Hz per topic; target '
        f'>= {TARGET_HZ:g} Hz per topic without loss: {judged}. Recorder CPU at 125 Hz: '
        f'{cpu_text}.',
    ]


if __name__ == '__main__':
    main()
