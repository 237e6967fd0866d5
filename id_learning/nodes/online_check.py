"""Online check: replay an excerpt of a bag's test part through the predictor node, in real time.

``online_check`` starts the ``replay`` and ``predictor`` nodes as separate processes, listens to
the reference and tau_u in this process over DDS, and compares what the predictor published with
the offline prediction of the same artifact on the same samples, both against the label.

The samples: the test part of the bag exactly as the trainer splits it (``load_datasets`` with the
preprocessing stored in the artifact, then ``segment_rows(dataset, 'test')``), from its start,
``seconds`` long (clipped to the test part). The offline inputs are that dataset's controller
inputs (the artifact's input definition: recorded q, v smoothed far above the motion's band, a by
central differences); the replay builds its reference with the same velocity smoothing. The
offline prediction runs on the excerpt's rows, so a sequence model starts its window at the
excerpt as the node does.

Against the label: tau_u is the torque the drive needs now, the label a low-passed torque; so
both the online and the offline excerpt are put into the model's offline torque along the whole
recording, which is then low-passed like the labels, and compared with the label on the excerpt
(the trainer's "through the filter" figure, restricted to the excerpt).

Why online and offline may differ: the predictor gets the replay's reference, which the replay
rebuilds from the recorded joint states with the same smoothing, but filtered over the played
span plus ``REFERENCE_PAD_S`` (10 s) on either side (not over the whole recording) and
differentiated over the bag's stamps as recorded (not snapped to the grid). The filter's edge
transients therefore leave small differences in q, v and a, reported as ``max_input_diff``; on
top, tau_u is clamped to the torque limits, and a sample the node's input queue dropped has no
tau_u. To tell these input differences from an error in the node, the artifact is also run
offline on exactly the references the predictor received: ``max_abs_node_error_nm`` must be at
floating-point level (float32 rounding for the networks, batched against one sample at a time; 0
for a float64 model such as RNEA+LQ).

Isolation: both nodes run in a private namespace (also their /diagnostics, and the replayed joint
states are remapped into it; no /clock), so the check cannot feed a live system that shares the
DDS domain. The domain is ``ROS_DOMAIN_ID`` from the environment unless given;
``ROS_AUTOMATIC_DISCOVERY_RANGE`` defaults to LOCALHOST.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import id_learning
from id_learning.errors import ConfigError, DatasetError, IdLearningError
from id_learning.nodes.process import NodeProcess

__all__ = ['OnlineCheckError', 'OnlineCheckResult', 'has_ros', 'online_check']

NS_PER_S = 1_000_000_000
#: Deadline for a node to start and connect (imports torch and scipy on a loaded machine) [s].
STARTUP_S = 120.0
#: After the replay ends, how long to wait for the last outputs and diagnostics [s].
DRAIN_S = 10.0
#: Deadline for a node to exit after SIGINT before it is killed [s].
STOP_S = 15.0
#: Characters of a node's log quoted in an error.
LOG_TAIL_CHARS = 3000
#: Listener queue depth [messages]: a whole second of stalls at 125 Hz.
LISTEN_DEPTH = 1000


class OnlineCheckError(IdLearningError):
    """A node failed to start or to finish, or the check produced no comparable sample."""


@dataclass(frozen=True, eq=False)
class OnlineCheckResult:
    """What the online check measured; arrays are (n,) per joint in ``joints`` order.

    Attributes:
        kind: the artifact's model kind.
        artifact, bag: what was checked.
        joints: joint names.
        test_start_s, test_s: start (from the bag's first sample) and length of the test part [s].
        excerpt_start_s, excerpt_s: start and length of the replayed excerpt [s].
        is_clipped: the test part is shorter than the requested excerpt.
        n_samples: samples in the excerpt.
        n_inputs: reference messages the listener received.
        n_outputs: tau_u messages received that belong to an excerpt sample.
        n_missing: excerpt samples without tau_u.
        rmse_online_nm: online tau_u against the label, through the label filter [N*m].
        rmse_offline_nm: offline prediction (controller inputs) against the label, through the
            filter, same samples.
        max_abs_online_offline_nm: max |online - offline| [N*m].
        max_abs_node_error_nm: max |online - the artifact on the received references| [N*m].
        max_input_diff: max |reference - dataset input| per 'q' [rad], 'v' [rad/s], 'a' [rad/s^2].
        predictor: the predictor's last /diagnostics (latency and compute in ms, counts).
        replay: the replay's last /diagnostics (lateness in ms, cycles).
        notes: what the reader should know (clipping, a bag the model was not trained on).
        wall_s: duration of the whole call [s].
    """

    kind: str
    artifact: Path
    bag: Path
    joints: tuple[str, ...]
    test_start_s: float
    test_s: float
    excerpt_start_s: float
    excerpt_s: float
    is_clipped: bool
    n_samples: int
    n_inputs: int
    n_outputs: int
    n_missing: int
    rmse_online_nm: np.ndarray
    rmse_offline_nm: np.ndarray
    max_abs_online_offline_nm: np.ndarray
    max_abs_node_error_nm: np.ndarray
    max_input_diff: dict[str, np.ndarray]
    predictor: dict[str, str]
    replay: dict[str, str]
    notes: tuple[str, ...] = ()
    wall_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (arrays as lists)."""
        out: dict[str, Any] = {}
        for name, value in self.__dict__.items():
            if isinstance(value, dict):
                out[name] = {key: _jsonable(item) for key, item in value.items()}
            else:
                out[name] = _jsonable(value)
        return out

    def summary(self) -> str:
        """A few lines for the terminal: counts, RMSE table, input differences, latency."""
        pred = self.predictor

        def ms(key: str) -> str:
            return f'{float(pred.get(key, "nan")):.3f}'

        width = max(10, *(len(j) + 2 for j in self.joints))
        header = ''.join(f'{j:>{width}}' for j in self.joints)

        def row(label: str, values: np.ndarray) -> str:
            return f'  {label:<38}' + ''.join(f'{x:>{width}.4g}' for x in values)

        clip = ' (clipped: the test part is shorter)' if self.is_clipped else ''
        lines = [
            f'online check of {self.kind} on {self.bag}: replayed {self.excerpt_s:.1f} s of the '
            f'test part ({self.test_start_s:.1f} s to {self.test_start_s + self.test_s:.1f} s of '
            f'the bag) from {self.excerpt_start_s:.1f} s in real time{clip}',
            f'  {self.n_samples} samples, {self.n_inputs} reference inputs, {self.n_outputs} '
            f'tau_u outputs, {self.n_missing} missing; {pred.get("clamped_samples", "?")} '
            f'clamped, {pred.get("out_of_range_samples", "?")} out of the training range, '
            f'{pred.get("rejected", "?")} rejected',
            f'  {"[N*m]":<38}{header}',
            row('RMSE online vs label, through filter', self.rmse_online_nm),
            row('RMSE offline vs label, through filter', self.rmse_offline_nm),
            row('max |online - offline|', self.max_abs_online_offline_nm),
            row('max |node - model(its inputs)|', self.max_abs_node_error_nm),
            '  online inputs vs offline inputs (replay reference vs training preprocessing): '
            + ', '.join(
                f'max |d{name}| {float(np.max(diff)):.3g} {unit}'
                for (name, diff), unit in zip(
                    self.max_input_diff.items(), ('rad', 'rad/s', 'rad/s^2'), strict=True
                )
            ),
            f'  predictor latency [ms]: receive-to-publish median {ms("latency_median_ms")}, '
            f'p99 {ms("latency_p99_ms")}, max {ms("latency_max_ms")}; compute median '
            f'{ms("compute_median_ms")}, p99 {ms("compute_p99_ms")}, max {ms("compute_max_ms")}'
            f' ({pred.get("latency_samples", "?")} samples)',
        ]
        if self.replay:
            rep = self.replay
            lines.append(
                f'  replay lateness [ms]: median {float(rep.get("lateness_median_ms", "nan")):.3f}'
                f', p99 {float(rep.get("lateness_p99_ms", "nan")):.3f}, max '
                f'{float(rep.get("lateness_max_ms", "nan")):.3f}; '
                f'{rep.get("late_cycles", "?")} cycles later than one period'
            )
        lines += [f'  note: {note}' for note in self.notes]
        lines.append(f'  ({self.wall_s:.1f} s)')
        return '\n'.join(lines)


def _jsonable(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return list(value)
    return value


# -- node processes -------------------------------------------------------------------------------
def _failure(node: NodeProcess, what: str) -> OnlineCheckError:
    return OnlineCheckError(
        f'{node.module} node {what} (exit status {node.process.poll()}); its log ends with:\n'
        f'{node.log()[-LOG_TAIL_CHARS:]}'
    )


def _node_environment(domain_id: int) -> dict[str, str]:
    """The whole environment (the wheels' bootstrap needs LD_LIBRARY_PATH) in our domain."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('AMENT_PREFIX_PATH', sys.prefix)
    env['PYTHONUNBUFFERED'] = '1'
    # The children import this very package, whatever their working directory.
    package_root = str(Path(id_learning.__file__).resolve().parents[1])
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [package_root, env.get('PYTHONPATH')]))
    return env


@contextmanager
def _node_processes(
    log_dir: Path, domain_id: int
) -> Iterator[Callable[[str, dict[str, object], dict[str, str]], NodeProcess]]:
    """Start nodes with ``start(module, parameters, remaps)``.

    Every node started is stopped on exit, also on an error or Ctrl-C.
    """
    started: list[NodeProcess] = []
    env = _node_environment(domain_id)

    def start(module: str, parameters: dict[str, object], remaps: dict[str, str]) -> NodeProcess:
        node = NodeProcess(module, parameters, log_dir / f'{module}.log', env, remaps)
        started.append(node)
        return node

    try:
        yield start
    finally:
        for node in started:  # all at once: each needs a moment to close
            node.interrupt()
        for node in started:
            node.stop(STOP_S)
        if any(node.was_killed for node in started):
            # A killed node leaves Fast DDS shared-memory files behind.
            fastdds = shutil.which('fastdds') or str(Path(sys.executable).parent / 'fastdds')
            if Path(fastdds).exists():
                subprocess.run(
                    [fastdds, 'shm', 'clean'], capture_output=True, timeout=60, check=False
                )


# -- the in-process listener ----------------------------------------------------------------------
def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


class _Listener:
    """An rclpy node in this process, spun by a thread: reference, tau_u and diagnostics."""

    def __init__(self, domain_id: int, namespace: str) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        from id_learning.nodes.qos import DIAGNOSTICS_QOS, reference_qos

        self.condition = threading.Condition()
        # (stamp, names, q, v, a) and (stamp, names, tau), in arrival order.
        self.references: list[
            tuple[int, tuple[str, ...], list[float], list[float], list[float]]
        ] = []
        self.outputs: list[tuple[int, tuple[str, ...], list[float]]] = []
        self.diagnostics: dict[str, dict[str, str]] = {}
        self.diagnostics_count: dict[str, int] = {}
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        try:
            self.node = rclpy.create_node(
                'online_check_listener', namespace=namespace, context=self.context
            )
            self.executor = SingleThreadedExecutor(context=self.context)
            self.executor.add_node(self.node)
            depth = reference_qos(LISTEN_DEPTH)
            self.node.create_subscription(JointTrajectory, 'reference', self._on_reference, depth)
            self.node.create_subscription(JointState, 'tau_u', self._on_tau_u, depth)
            self.node.create_subscription(
                DiagnosticArray, 'diagnostics', self._on_diagnostics, DIAGNOSTICS_QOS
            )
        except Exception:
            self.context.try_shutdown()
            raise
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='online_check', daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_reference(self, msg: Any) -> None:
        point = msg.points[0]
        item = (
            _stamp_ns(msg.header.stamp),
            tuple(msg.joint_names),
            list(point.positions),
            list(point.velocities),
            list(point.accelerations),
        )
        with self.condition:
            self.references.append(item)
            self.condition.notify_all()

    def _on_tau_u(self, msg: Any) -> None:
        item = (_stamp_ns(msg.header.stamp), tuple(msg.name), list(msg.effort))
        with self.condition:
            self.outputs.append(item)
            self.condition.notify_all()

    def _on_diagnostics(self, msg: Any) -> None:
        with self.condition:
            for status in msg.status:
                self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}
                self.diagnostics_count[status.name] = (
                    self.diagnostics_count.get(status.name, 0) + 1
                )
            self.condition.notify_all()

    def wait_for(
        self,
        predicate: Callable[[], bool],
        timeout: float,
        what: str,
        watched: list[NodeProcess],
    ) -> bool:
        """Wait until predicate() holds; False on timeout; a node that exited raises."""
        deadline = time.monotonic() + timeout
        with self.condition:
            while not predicate():
                for node in watched:
                    if not node.is_running:
                        raise _failure(node, f'exited while waiting for {what}')
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.condition.wait(min(left, 0.1))
        return True

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


# -- the check ------------------------------------------------------------------------------------
@dataclass
class _Plan:
    """The excerpt: dataset rows [start, stop) and the replay's window on the bag."""

    start: int
    stop: int
    test_start: int
    test_stop: int
    notes: list[str] = field(default_factory=list)


def has_ros() -> bool:
    """Whether rclpy (ROS 2 Jazzy) can be imported, i.e. the online check can run here."""
    return importlib.util.find_spec('rclpy') is not None


def _say(progress: bool, text: str) -> None:
    if progress:
        print(f'online check: {text}', flush=True)


def _domain(domain_id: int | None) -> int:
    if domain_id is None:
        text = os.environ.get('ROS_DOMAIN_ID', '').strip() or '0'
        try:
            domain_id = int(text)
        except ValueError:
            raise ConfigError(f'ROS_DOMAIN_ID must be an integer, got {text!r}') from None
    if not 0 <= domain_id <= 232:
        raise ConfigError(f'ROS domain id must be in [0, 232], got {domain_id}')
    return domain_id


def _rmse(prediction: np.ndarray, target: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((prediction - target) ** 2, axis=0))


def _columns(names: tuple[str, ...], joints: tuple[str, ...], what: str) -> list[int]:
    """Column of each of ``joints`` in a message with ``names``."""
    if sorted(names) != sorted(joints):
        raise OnlineCheckError(f'{what} carries joints {list(names)}, expected {list(joints)}')
    return [names.index(joint) for joint in joints]


def online_check(
    bag: Path,
    robot_config_path: Path,
    artifact: Path,
    *,
    seconds: float = 30.0,
    out: Path | None = None,
    domain_id: int | None = None,
    input_depth: int | None = None,
    progress: bool = True,
) -> OnlineCheckResult:
    """Replay ``seconds`` of the bag's test part through the predictor node and compare offline.

    Args:
        bag: the recording (the bag contract); its test part is the trainer's.
        robot_config_path: robot config YAML the artifact was trained for.
        artifact: model artifact folder (any kind).
        seconds: length of the excerpt [s], from the start of the test part; clipped to it.
        out: also write the result as JSON here.
        domain_id: ROS domain; None: ``ROS_DOMAIN_ID`` from the environment (else 0).
        input_depth: the predictor's reference queue depth; None: the node's default, with
            which a machine stall longer than that many cycles drops samples (reported as
            missing), as it would in production. A depth of the excerpt's length loses none.
        progress: print what is happening.

    Returns:
        The measured result; ``summary()`` gives the text.

    Raises:
        CheckpointError: the artifact is invalid or not for this robot.
        BagError, DatasetError: the bag is unusable or the excerpt is too short.
        OnlineCheckError: rclpy is missing, a node failed to start or finish (with the tail of
            its log), or no tau_u came back.
        ConfigError: ``seconds`` or the domain id is out of range.
    """
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.evaluation.scoring import predict_along
    from id_learning.models.registry import load_model
    from id_learning.robot.config import load_robot_config
    from id_learning.training.trainer import (
        bag_sha256,
        load_datasets,
        preprocess_from_dict,
        segment_rows,
    )

    began = time.monotonic()
    if not has_ros():
        raise OnlineCheckError(
            'rclpy (ROS 2 Jazzy) is not installed: the online check needs the ROS nodes; see '
            'README, Quick start'
        )
    if not seconds > 0:
        raise ConfigError(f'seconds must be > 0, got {seconds}')
    domain = _domain(domain_id)
    bag, artifact, robot_config_path = Path(bag), Path(artifact), Path(robot_config_path)
    robot = load_robot_config(robot_config_path)
    model = load_model(artifact, robot)
    kind = model.kind
    joints = tuple(model.joint_names)
    metadata = json.loads((artifact / 'model.json').read_text(encoding='utf-8'))
    notes: list[str] = []
    if metadata.get('preprocessing'):
        preprocess = preprocess_from_dict(metadata['preprocessing'])
    else:
        preprocess = PreprocessConfig()
        notes.append('the artifact stores no preprocessing: the default (motor target) is used')
    period_ns = round(robot.ipo_period_s * NS_PER_S)
    smoothing = np.asarray(
        preprocess.input_smoothing_hz
        if preprocess.input_smoothing_hz is not None
        else robot.input_smoothing_hz
    )
    # The replay takes one smoothing cut-off for every joint (0: the robot config's).
    smoothing_hz = float(smoothing[0]) if np.all(smoothing == smoothing[0]) else 0.0
    if not smoothing_hz and not np.array_equal(smoothing, robot.input_smoothing_hz):
        notes.append(
            f'the artifact smooths velocities at {smoothing.tolist()} Hz per joint; the replay '
            f"takes one value, so it uses the robot config's {robot.input_smoothing_hz.tolist()}"
        )
    namespace = f'/online_check_{os.getpid()}'
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # before rclpy.init

    with (
        tempfile.TemporaryDirectory(prefix='online_check_') as tmp,
        _node_processes(Path(tmp), domain) as start,
    ):
        _say(progress, f'starting the predictor ({kind}, domain {domain}, namespace {namespace})')
        predictor = start(
            'predictor',
            {
                'artifact': str(artifact.resolve()),
                'robot_config': str(robot_config_path.resolve()),
                'input_topic': 'reference',
                'output_topic': 'tau_u',
                'diagnostics_period_s': 0.25,
                'latency_window': max(4096, round(seconds * NS_PER_S / period_ns) + 64),
                **({} if input_depth is None else {'input_depth': input_depth}),
            },
            {'__ns': namespace, '/diagnostics': f'{namespace}/diagnostics'},
        )

        # While the node imports torch: the trainer's preprocessing and split of this bag.
        _say(progress, f'preprocessing {bag} as the trainer does ({preprocess.target} labels)')
        dataset = load_datasets([bag], robot, preprocess, progress=False)[0]
        test_start, test_stop = segment_rows(dataset, 'test')[0]
        n_wanted = round(seconds * NS_PER_S / period_ns)
        stop = min(test_start + n_wanted, test_stop)
        if stop - test_start < 3:
            raise DatasetError(
                f'{bag}: the test part has {test_stop - test_start} samples; the online check '
                'needs at least 3'
            )
        is_clipped = stop - test_start < n_wanted
        if is_clipped:
            notes.append(
                f'the test part lasts {(test_stop - test_start) * robot.ipo_period_s:.1f} s: '
                f'replayed all of it instead of {seconds:g} s'
            )
        trained_on = {
            entry.get('sha256') for entry in metadata.get('training_data', {}).get('bags', [])
        }
        if bag_sha256(bag) not in trained_on:
            notes.append(
                'the bag is not one of the artifact\'s training bags: its "test part" is only its '
                'last share in time'
            )
        controller = dataset.controller
        along = predict_along(model, controller, dataset.recording_rows())
        excerpt = controller.take(slice(test_start, stop))
        offline = model.predict(excerpt.q, excerpt.v, excerpt.a)
        stamps = dataset.stamps_ns
        # The replay counts its offset from the bag's first stamp, which is the dataset's first
        # (regularise keeps it); half a period of margin on each side against rounding.
        start_offset_s = (int(stamps[test_start] - stamps[0]) - period_ns // 2) / NS_PER_S
        duration_s = (int(stamps[stop - 1] - stamps[test_start]) + period_ns) / NS_PER_S
        excerpt_start_s = (stamps[test_start] - stamps[0]) / NS_PER_S
        excerpt_s = (stop - test_start) * robot.ipo_period_s

        listener = _Listener(domain, namespace)
        try:
            predictor_name = f'id_learning{namespace}/predictor'
            replay_name = f'id_learning{namespace}/replay'

            def predictor_values() -> dict[str, str]:
                return listener.diagnostics.get(predictor_name, {})

            _say(progress, 'waiting for the predictor to connect')
            # Matched on the writer side: no tau_u can be lost to discovery.
            if not listener.wait_for(
                lambda: int(predictor_values().get('tau_u_subscriptions', 0)) >= 1,
                STARTUP_S,
                'the predictor to connect',
                [predictor],
            ):
                raise _failure(predictor, f'did not connect within {STARTUP_S:g} s')
            _say(
                progress,
                f'replaying {excerpt_s:.1f} s of the test part from {excerpt_start_s:.1f} s in '
                'real time',
            )
            js_topic = robot.topics.joint_states
            replay = start(
                'replay',
                {
                    'bag': str(bag.resolve()),
                    'robot_config': str(robot_config_path.resolve()),
                    'topics': [js_topic],
                    'reference_source': js_topic,
                    'reference_topic': 'reference',
                    'reference_inputs': 'controller',
                    'reference_smoothing_hz': smoothing_hz,
                    'start_offset_s': max(start_offset_s, 0.0),
                    'duration_s': duration_s,
                    'publish_clock': False,
                    # The predictor's and this listener's reference subscriptions.
                    'wait_for_subscribers': 2,
                    'wait_timeout_s': STARTUP_S,
                    'diagnostics_period_s': 1.0,
                },
                {
                    '__ns': namespace,
                    '/diagnostics': f'{namespace}/diagnostics',
                    js_topic: f'{namespace}/replayed{js_topic}',
                },
            )
            deadline = time.monotonic() + STARTUP_S + excerpt_s * 1.5
            while replay.is_running:
                if not predictor.is_running:
                    raise _failure(predictor, 'exited during the replay')
                if time.monotonic() > deadline:
                    raise _failure(replay, 'did not finish in time')
                with suppress(subprocess.TimeoutExpired):
                    replay.process.wait(0.2)
            if replay.process.returncode != 0:
                raise _failure(replay, 'failed')
            n_inputs = len(listener.references)
            _say(progress, f'replay done: {n_inputs} references; waiting for the last outputs')
            with listener.condition:
                reports = listener.diagnostics_count.get(predictor_name, 0)

            def is_drained() -> bool:
                values = predictor_values()
                if len(listener.outputs) < int(values.get('published', 0)):
                    return False  # tau_u still on its way
                if int(values.get('received', -1)) >= len(listener.references):
                    return True
                # Some references never reached the node. The replay ends once its samples are
                # acknowledged, i.e. in the node's input queue: two reports later it has handled
                # all it will ever get.
                return listener.diagnostics_count.get(predictor_name, 0) >= reports + 2

            listener.wait_for(
                is_drained,
                DRAIN_S,
                'the last tau_u',
                [predictor],
            )
            with listener.condition:
                references = list(listener.references)
                outputs = list(listener.outputs)
                predictor_diag = dict(predictor_values())
                replay_diag = dict(listener.diagnostics.get(replay_name, {}))
        finally:
            listener.close()

    # -- comparison (after the nodes are stopped: nothing competes for the cores) ---------------
    def row_of(stamp: int) -> int | None:
        slot = round((stamp - int(stamps[0])) / period_ns)
        if test_start <= slot < stop and abs(stamp - int(stamps[slot])) <= period_ns // 4:
            return slot
        return None

    ref_by_row: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for stamp, names, q, v, a in sorted(references, key=lambda item: item[0]):
        row = row_of(stamp)
        if row is not None:
            cols = _columns(names, joints, 'the reference')
            ref_by_row[row] = (np.asarray(q)[cols], np.asarray(v)[cols], np.asarray(a)[cols])
    tau_by_row: dict[int, np.ndarray] = {}
    for stamp, names, effort in outputs:
        row = row_of(stamp)
        if row is not None:
            tau_by_row[row] = np.asarray(effort)[_columns(names, joints, 'tau_u')]
    matched = sorted(set(tau_by_row) & set(ref_by_row))
    if not matched:
        raise OnlineCheckError(
            f'no tau_u came back for the {stop - test_start} samples of the excerpt '
            f'({len(references)} references and {len(outputs)} outputs received); predictor '
            f'diagnostics: {predictor_diag}'
        )
    index = np.asarray(matched)
    online = np.vstack([tau_by_row[r] for r in matched])
    offline_matched = offline[index - test_start]
    label = dataset.tau[index]

    def through_filter(excerpt_torque: np.ndarray) -> np.ndarray:
        spliced = along.copy()
        spliced[index] = excerpt_torque
        return dataset.filter_like_labels(spliced)[index]

    ref_rows = np.asarray(sorted(ref_by_row))
    q_ref, v_ref, a_ref = (np.vstack([ref_by_row[r][k] for r in ref_rows]) for k in range(3))
    input_diff = {
        'q': np.max(np.abs(q_ref - controller.q[ref_rows]), axis=0),
        'v': np.max(np.abs(v_ref - controller.v[ref_rows]), axis=0),
        'a': np.max(np.abs(a_ref - controller.a[ref_rows]), axis=0),
    }
    # The artifact on exactly the node's inputs: the references it answered, in order (a sequence
    # model's window skips a dropped sample as the node's does), clamped as the node clamps.
    q_node, v_node, a_node = (np.vstack([ref_by_row[r][k] for r in matched]) for k in range(3))
    limit = robot.limits.torque
    node_model = np.clip(model.predict(q_node, v_node, a_node), -limit, limit)
    n_missing = (stop - test_start) - len(tau_by_row)
    if n_missing:
        notes.append(
            f'{n_missing} samples got no tau_u: the predictor received '
            f'{predictor_diag.get("received", "?")} of {n_inputs} references and rejected '
            f'{predictor_diag.get("rejected", "?")}; its input queue keeps the newest '
            'input_depth samples, so a stall of the machine drops older ones'
        )
    result = OnlineCheckResult(
        kind=kind,
        artifact=artifact,
        bag=bag,
        joints=joints,
        test_start_s=(stamps[test_start] - stamps[0]) / NS_PER_S,
        test_s=(test_stop - test_start) * robot.ipo_period_s,
        excerpt_start_s=excerpt_start_s,
        excerpt_s=excerpt_s,
        is_clipped=is_clipped,
        n_samples=stop - test_start,
        n_inputs=n_inputs,
        n_outputs=len(tau_by_row),
        n_missing=n_missing,
        rmse_online_nm=_rmse(through_filter(online), label),
        rmse_offline_nm=_rmse(through_filter(offline_matched), label),
        max_abs_online_offline_nm=np.max(np.abs(online - offline_matched), axis=0),
        max_abs_node_error_nm=np.max(np.abs(online - node_model), axis=0),
        max_input_diff=input_diff,
        predictor=predictor_diag,
        replay=replay_diag,
        notes=tuple(notes),
        wall_s=time.monotonic() - began,
    )
    if out is not None:
        out = Path(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result.to_dict(), indent=1) + '\n', encoding='utf-8')
    return result
