"""Fault cases at the nodes as processes: bad settings and inputs, a killed recorder, a killed
replay, a reference far faster than the IPO rate, the online check on a wrong folder.

Each case starts real node processes (``id_learning.nodes.process``) in a DDS domain of its own,
waits on conditions with deadlines and stops every process it started.
"""

from __future__ import annotations

import random
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from fault_kit import ROBOT_FILE, Case, Fixtures, Outcome, broken_bag, raises, with_value

__all__ = ['node_cases']

#: Deadline for a node that must exit by itself, or reach a state [s].
DEADLINE_S = 60.0


def _wait_until(condition: Callable[[], bool], timeout: float = DEADLINE_S) -> bool:
    """Poll ``condition`` until it holds or the deadline passes; whether it held."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


@contextmanager
def _nodes(log_dir: Path, *, listen: bool = False) -> Iterator[tuple[Any, Any]]:
    """(start, listener) in a DDS domain of its own, the nodes' logs in ``log_dir``.

    The listener (an in-process subscriber of the reference and tau_u) only when ``listen``;
    every node is stopped and the listener closed afterwards.
    """
    from id_learning.nodes.listener import Listener
    from id_learning.nodes.process import node_processes

    log_dir.mkdir(parents=True, exist_ok=True)
    domain = random.SystemRandom().randint(1, 101)  # below Linux's ephemeral ports
    listener = Listener(domain, '/') if listen else None
    try:
        with node_processes(log_dir, domain) as start:
            yield start, listener
    finally:
        if listener is not None:
            listener.close()


def _refused(log_dir: Path, module: str, parameters: dict[str, object],
             expect: tuple[str, ...]) -> Outcome:  # fmt: skip
    """A node that must exit non-zero at start, its log naming every word in ``expect``."""
    with _nodes(log_dir) as (start, _):
        node = start(module, parameters, {})
        if not _wait_until(lambda: not node.is_running):
            return Outcome('silently_accepted', f'{module} still running: {node.log()[-300:]}')
        status, said = node.process.returncode, node.log()
    if status == 0:
        return Outcome('silently_accepted', said[-400:])
    if 'Traceback' in said:
        return Outcome('traceback', said[-400:])
    missing = [word for word in expect if word.lower() not in said.lower()]
    return Outcome('clear_error' if not missing else 'silently_accepted', said[-400:])


def _played_cycles(bag: Path, robot: object) -> int:
    from id_learning.nodes.params import ReplayConfig
    from id_learning.nodes.replay import build_plan

    return len(build_plan(ReplayConfig(bag=str(bag)), robot).cycles)  # type: ignore[arg-type]


def _killed_recorder(fx: Fixtures) -> Outcome:
    """SIGKILL the recorder after a replay: `bag recover` must give back every message."""
    from id_learning.bag import bag_info
    from id_learning.bag.recover import recover_bag

    out = fx.path('killed_recorder_bag')
    played = sum(t.count for t in bag_info(fx.bag).topics)
    with _nodes(fx.path('killed_recorder_logs')) as (start, _):
        recorder = start('recorder', {'output': str(out), 'flush_period_s': 0.25}, {})
        replay = start('replay', {
            'bag': str(fx.bag), 'rate': 4.0, 'reference_mode': 'none', 'publish_clock': False,
            'wait_for_subscribers': 2}, {})  # fmt: skip
        if not _wait_until(lambda: not replay.is_running) or replay.process.returncode != 0:
            return Outcome('traceback', f'replay failed: {replay.log()[-300:]}')
        # Everything received is on disk within two flush periods: wait for the file to settle.
        sizes: list[int] = []

        def settled() -> bool:
            sizes.append(sum(f.stat().st_size for f in out.glob('*.mcap')))
            return len(sizes) > 12 and sizes[-1] == sizes[-12] > 0

        _wait_until(settled, 10.0)
        recorder.kill()
    try:
        report = recover_bag(out)
    except Exception as error:
        return Outcome('traceback', f'{type(error).__name__}: {error}')
    kept = sum(t.count for t in bag_info(out).topics)
    kind = 'handled' if kept == played else 'data_lost'
    return Outcome(kind, f'recorder SIGKILLed after the replay: {report.summary()}; the bag '
                         f'holds {kept} of the {played} messages played')  # fmt: skip


def _overload(fx: Fixtures, rate: float) -> Outcome:
    """A reference at ``rate`` times the IPO rate: every sample received or counted skipped."""
    import re

    cycles = _played_cycles(fx.bag, fx.robot)
    with _nodes(fx.path(f'overload_{rate:g}'), listen=True) as (start, listener):
        predictor = start('predictor', {
            'artifact': str(fx.artifact), 'input_topic': '/reference',
            'stale_after_cycles': 100000}, {})  # fmt: skip
        # The play at 20x lasts a second or two: the listener must know the predictor's output
        # before it starts (the replay waits only for the reference's subscribers).
        if not _wait_until(lambda: listener.node.count_publishers('/tau_u') >= 1):
            return Outcome('traceback', f'tau_u never appeared: {predictor.log()[-300:]}')
        replay = start('replay', {
            'bag': str(fx.bag), 'rate': rate, 'topics': ['/joint_states'],
            'publish_clock': False, 'wait_for_subscribers': 2}, {})  # fmt: skip
        if not _wait_until(lambda: not replay.is_running) or replay.process.returncode != 0:
            return Outcome('traceback', f'replay failed: {replay.log()[-300:]}')
        counts: list[int] = []

        def drained() -> bool:  # the predictor has served what was queued
            counts.append(len(listener.outputs))
            return len(counts) > 10 and counts[-1] == counts[-10]

        _wait_until(drained, 20.0)
        status = predictor.stop()
        said = predictor.log()
        sent = sorted(stamp for stamp, *_ in listener.references)
        served = sorted(stamp for stamp, *_ in listener.outputs)
    pattern = r'(\d+) samples received, (\d+) published.*?(\d+) cycles skipped, (\d+) late'
    found = re.search(pattern, said, re.S)
    if status != 0 or found is None:
        return Outcome('traceback', said[-400:])
    received, published, skipped, late = (int(x) for x in found.groups())
    # A receiver can count what it missed only from its first sample on (a gap in the stamps);
    # what was lost before that, while discovery settled, it never knew of. The span is taken
    # from the stamps served, on the IPO grid (a listener may miss messages itself).
    period_ns = round(fx.robot.ipo_period_s * 1e9)  # type: ignore[attr-defined]
    span = round((served[-1] - served[0]) / period_ns) + 1 if served else 0
    latency = re.search(r'latency median ([\d.]+) ms, p99 ([\d.]+) ms', said)
    latency_text = latency.group(0) if latency else 'no latency reported'
    text = (f'{len(sent)} references at {rate:g}x the IPO rate, {span} from the first served to '
            f'the last: {received} received ({published} published, {late} late), {skipped} '
            f'counted as skipped; {latency_text}')  # fmt: skip
    # Within the span served, everything is accounted for. Before it, what the replay sent while
    # the predictor's side of discovery was still matching is lost to any receiver (a quarter of
    # the play at 20x once, on a loaded CI machine): the span must still hold most of the play.
    counted = received + skipped >= span >= 0.5 * cycles
    return Outcome('handled' if counted else 'silently_accepted', text)


def _killed_replay(fx: Fixtures) -> Outcome:
    """The replay SIGKILLed mid-play: the predictor says stale once and keeps running."""
    with _nodes(fx.path('killed_replay'), listen=True) as (start, listener):
        # A stale threshold of 25 cycles (200 ms): a loaded machine's stall during the play
        # must not pass for the silence the kill leaves.
        predictor = start('predictor', {
            'artifact': str(fx.artifact), 'input_topic': '/reference',
            'stale_after_cycles': 25}, {})  # fmt: skip
        replay = start('replay', {
            'bag': str(fx.bag), 'topics': ['/joint_states'], 'publish_clock': False,
            'wait_for_subscribers': 2}, {})  # fmt: skip
        if not _wait_until(lambda: len(listener.outputs) >= 50):
            return Outcome('traceback', f'no tau_u: {predictor.log()[-300:]}')
        replay.kill()
        stale = _wait_until(lambda: 'reference stale' in predictor.log(), 10.0)
        alive = predictor.is_running
        status = predictor.stop()
        said = predictor.log()
    if not alive or status != 0:
        return Outcome('traceback', said[-400:])
    if stale and said.count('reference stale: no valid sample') == 1:
        return Outcome('handled', 'replay SIGKILLed mid-play: the predictor reported the stale '
                                  'reference once and stopped cleanly')  # fmt: skip
    return Outcome('silently_accepted', said[-400:])


def node_cases(fx: Fixtures) -> Iterator[Case]:
    try:
        import rclpy  # noqa: F401 -- the nodes need ROS 2
    except ImportError:
        return
    assert fx.run_dir is not None
    logs = fx.path('node_logs')
    rec = fx.recording

    def nan_artifact() -> Path:
        """The artifact with a NaN in its target scaler (a fit gone wrong, hash and all)."""
        import json

        folder = fx.path('node_nan_artifact')
        shutil.copytree(fx.artifact, folder)
        meta = folder / 'model.json'
        data = json.loads(meta.read_text())
        data['target_scaler']['low'][0] = float('nan')
        meta.write_text(json.dumps(data))
        return folder

    refusals: dict[str, tuple[str, Callable[[], dict[str, object]], tuple[str, ...]]] = {
        'predictor without an artifact': (
            'predictor', lambda: {'artifact': str(fx.path('no_such_artifact'))},
            ('no_such_artifact',)),
        'predictor on an artifact with a NaN scaler': (
            'predictor', lambda: {'artifact': str(nan_artifact())}, ('target_scaler', 'nan')),
        'predictor with an unknown out_of_range': (
            'predictor', lambda: {'artifact': str(fx.artifact), 'out_of_range': 'maybe'},
            ('out_of_range',)),
        'predictor for another robot': (
            'predictor', lambda: {'artifact': str(fx.artifact),
                                  'robot_config': str(ROBOT_FILE.parent / 'ur5.yaml')},
            ('robot',)),
        'replay of a bag with a NaN position': (
            'replay', lambda: {'bag': str(broken_bag(
                fx, 'node_replay_nan', position=with_value(rec.position, 60, 0, np.nan)))},
            ('sample 60',)),
        'replay of a missing bag': (
            'replay', lambda: {'bag': str(fx.path('no_such_bag'))}, ('no_such_bag',)),
        'recorder into an existing bag': (
            'recorder', lambda: {'output': str(fx.bag)}, ('overwrite',)),
        'recorder with a type per topic missing': (
            'recorder', lambda: {'topics': ['/a', '/b'],
                                 'msg_types': ['sensor_msgs/msg/JointState']}, ('msg_types',)),
    }  # fmt: skip
    for name, (module, parameters, expect) in refusals.items():
        yield Case(name, module, lambda m=module, p=parameters, e=expect, n=name:
                   _refused(logs / n.replace(' ', '_'), m, p(), e))  # fmt: skip
    yield Case('recorder SIGKILLed after a replay', 'recorder', lambda: _killed_recorder(fx))
    yield Case('replay SIGKILLed mid-play', 'predictor', lambda: _killed_replay(fx))
    yield Case('reference at 20x the IPO rate', 'predictor', lambda: _overload(fx, 20.0))

    def online_check_on_a_folder() -> Outcome:
        from id_learning.errors import CheckpointError
        from id_learning.online_check import online_check

        return raises(lambda: online_check(fx.bag, ROBOT_FILE, fx.path('not_an_artifact'),
                                           seconds=1.0, progress=False),
                      CheckpointError, ('not_an_artifact',))  # fmt: skip

    yield Case('online check on a folder that is no artifact', 'online check',
               online_check_on_a_folder)  # fmt: skip
