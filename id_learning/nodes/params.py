"""The nodes' parameters: one frozen dataclass per node, declared to ROS from its fields.

Each field is a ``param`` (``nodes.param_schema``): its ROS description (with units), whether it
is read-only at runtime, and what it may hold (``choices``, a ``low``/``high`` range of finite
numbers, or a ``topic`` name). ``__post_init__`` checks the schema and the rules that tie fields
together, naming the key and the value. A node declares every field (``declare_parameters``),
reads one validated snapshot (``read_snapshot``; errors name the node) and, for the fields that
may change at runtime, validates a change by building a new snapshot before accepting it.

A new parameter is one field, e.g. ``slew_limit: float = param(0.0, 'What it does [unit];
0 = off.', low=0.0, read_only=False)``: its checks come from the schema; ``__post_init__``
gains a line only for a rule between fields.

``config/nodes.yaml`` holds all three nodes' parameters in the ROS 2 parameter-file format;
``load_node_config`` reads it without ROS (and rejects unknown keys), for tests and tools.
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from pathlib import Path
from typing import cast

from id_learning.config_io import not_a_file
from id_learning.errors import ConfigError
from id_learning.nodes.param_ros import declare_parameters, read_snapshot
from id_learning.nodes.param_schema import (
    MAX_SECONDS,
    TopicChecks,
    check_schema,
    config_from_mapping,
    load_node_config,
    log_change,
    param,
    refuse_shared_topics,
    validate_change,
)
from id_learning.predictor.config import GuardConfig, OutOfRangeAction
from id_learning.robot.config import RobotConfig

__all__ = [
    'EXECUTORS',
    'PredictorNodeConfig',
    'RecorderConfig',
    'ReplayConfig',
    'config_from_mapping',
    'declare_parameters',
    'guard_config',
    'load_node_config',
    'log_change',
    'read_snapshot',
    'refuse_shared_topics',
    'resolve_robot_config',
    'validate_change',
]

PACKAGE = 'id_learning'
DEFAULT_ROBOT_CONFIG = 'mabi_max100.yaml'
EXECUTORS = ('single_threaded', 'events')
JOINT_STATE = 'sensor_msgs/msg/JointState'
#: The deepest queue a node keeps [messages], and the most threads it starts.
MAX_QUEUE_DEPTH = 1_000_000
MAX_THREADS = 256
#: The shortest and longest period of a node's timers [s]: a shorter one spins a CPU core on
#: reports nobody reads; a longer one overflows the timer's int64 nanoseconds.
MIN_PERIOD_S = 0.05
MAX_PERIOD_S = 3600.0
#: The smallest recorder split [s], [MiB] (besides 0 = off): a new file per message otherwise.
MIN_SPLIT_S = 0.1
MIN_SPLIT_MIB = 0.1
#: The largest split [MiB] (about a PiB: its bytes fit an int64), the slowest replay rate [-].
MAX_SPLIT_MIB, MIN_RATE = 1e9, 1e-3
#: The smallest torque_limit_scale: the share the predictor core accepts (``GuardConfig``).
MIN_TORQUE_LIMIT_SCALE = 1e-6
#: The shortest repeat of the predictor's 'still stale' line [s] (besides 0 = once).
MIN_LOG_PERIOD_S = 1.0
#: What a node publishes on its own fixed topics (a topic parameter naming one is refused).
DIAGNOSTICS = {'/diagnostics': 'diagnostics (diagnostic_msgs/msg/DiagnosticArray)'}
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'


# -- the three nodes ------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecorderConfig:
    """Parameters of the recorder node."""

    output: str = param(
        '',
        'Bag folder to write (rosbag2, MCAP storage). Empty: recordings/<UTC date-time> in '
        'the working directory.',
    )
    overwrite: bool = param(False, 'Replace a bag at output (only a bag: nothing else).')
    topics: tuple[str, ...] = param(
        ('/joint_states', '/motor_currents'),
        'Topics to record (the bag contract).',
        topic=True,
        non_empty='give at least one topic to record',
        unique=True,
    )
    msg_types: tuple[str, ...] = param(
        (JOINT_STATE, JOINT_STATE),
        'Message type of each topic, as pkg/msg/Type.',
        non_empty='give one pkg/msg/Type per topic',
        msg_type=True,
    )
    reliability: str = param(
        'reliable',
        'Subscription reliability: reliable matches reliable publishers only, best_effort '
        'matches both (without retransmission).',
        choices=('reliable', 'best_effort'),
    )
    qos_depth: int = param(
        1000,
        'Subscription queue depth [messages] (KEEP_LAST): 8 s at 125 Hz, 0.5 s at 2 kHz of '
        'writer stalls absorbed.',
        low=1,
        high=MAX_QUEUE_DEPTH,
    )
    flush_period_s: float = param(
        0.25,
        'Period of the flush that ends the MCAP chunk and pushes it to the file [s]; bounds what '
        'a SIGKILL can lose. From 0.01 s (a chunk per flush) to 0.5 s.',
        low=0.01,
        high=0.5,
    )
    chunk_kib: int = param(
        512,
        'MCAP chunk size [KiB] at which a chunk is closed between flushes.',
        low=1,
        high=1_048_576,
    )
    split_duration_s: float = param(
        0.0,
        'Start a new .mcap file after this much log time [s], at least 0.1 s; 0 = no split by '
        'duration.',
        low=0.0,
        high=MAX_SECONDS,
        zero_or_at_least=(MIN_SPLIT_S, 'off', 's'),  # a file per message otherwise
    )
    split_size_mib: float = param(
        0.0,
        'Start a new .mcap file at this file size [MiB], at least 0.1 MiB; 0 = no split by size.',
        low=0.0,
        high=MAX_SPLIT_MIB,
        zero_or_at_least=(MIN_SPLIT_MIB, 'off', 'MiB'),
    )
    diagnostics_period_s: float = param(
        1.0,
        'Period of the counts published on /diagnostics [s], from 0.05 s (20 '
        'reports a second) to an hour.',
        read_only=False,
        low=MIN_PERIOD_S,
        high=MAX_PERIOD_S,
    )
    executor: str = param(
        'single_threaded', 'rclpy executor that runs the callbacks.', choices=EXECUTORS
    )

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        check_schema(self)  # empty, repeated or malformed topics and msg_types among the rest
        if len(self.topics) != len(self.msg_types):
            raise ConfigError(
                f'each recorded topic needs its type: topics {list(self.topics)} and msg_types '
                f'{list(self.msg_types)} differ in length'
            )
        refuse_shared_topics(self)

    @property
    def split_duration_ns(self) -> int | None:
        """``split_duration_s`` [ns] for the writer; None: no split by duration."""
        return round(self.split_duration_s * 1e9) or None

    @property
    def split_bytes(self) -> int | None:
        """``split_size_mib`` [bytes] for the writer; None: no split by size."""
        return round(self.split_size_mib * (1 << 20)) or None

    def topic_checks(self) -> TopicChecks:
        """Groups of (topic by parameter, the node's own topics) no two of which may meet.

        Its own /diagnostics may be recorded (with every other node's reports), as the
        DiagnosticArray it is: recorded as another type, the two would clash.
        """
        named = {f'topics[{k}]': topic for k, topic in enumerate(self.topics)}
        typed = zip(named.items(), self.msg_types, strict=True)
        foreign = {name: topic for (name, topic), kind in typed if kind != DIAGNOSTIC_ARRAY}
        return [(named, {}), (foreign, DIAGNOSTICS)]

    def bag_path(self, now: datetime.datetime | None = None) -> Path:
        """The bag folder to write."""
        if self.output:
            return Path(self.output).expanduser()
        now = now or datetime.datetime.now(datetime.UTC)
        return Path('recordings') / now.strftime('%Y%m%dT%H%M%SZ')


@dataclass(frozen=True)
class ReplayConfig:
    """Parameters of the replay node."""

    bag: str = param('', 'Bag folder to play (rosbag2, MCAP or SQLite storage). Required.')
    topics: tuple[str, ...] = param(
        ('/joint_states', '/motor_currents'),
        'Topics of the bag to publish, each on its own name with its original bytes.',
        topic=True,
    )
    robot_config: str = param(
        '',
        'Robot config YAML (joints, IPO period, label and input cut-offs). Empty: the '
        'package config/mabi_max100.yaml.',
    )
    rate: float = param(
        1.0,
        'Playback speed factor [-]: 2.0 plays twice as fast, 0.001 (the slowest) plays a second '
        'of the bag in about 17 minutes. A play longer than an hour of wall time is said as it '
        'starts.',
        low=MIN_RATE,
        high=100.0,
    )
    loop: bool = param(False, 'Start again from the start offset at the end.')
    start_offset_s: float = param(
        0.0,
        'Skip this much of the bag from its first sample [s]; beyond its end nothing is played.',
        low=0.0,
        high=MAX_SECONDS,
    )
    duration_s: float = param(
        0.0,
        'Play this much of the bag [s]; 0, or more than it holds = to the end.',
        low=0.0,
        high=MAX_SECONDS,
    )
    publish_clock: bool = param(
        True, 'Publish /clock with each cycle stamp (for use_sim_time nodes).'
    )
    timing: str = param(
        'stamp',
        'Schedule by header stamps (the IPO grid of a recording) or by the bag log times.',
        choices=('stamp', 'log_time'),
    )
    reference_mode: str = param(
        'trajectory',
        'Reference for the predictor: trajectory = trajectory_msgs/JointTrajectory with one '
        'point (q, v, a); joint_state = sensor_msgs/JointState with q and v; none = off.',
        choices=('trajectory', 'joint_state', 'none'),
    )
    reference_topic: str = param('reference', 'Topic of the reference.', topic=True)
    reference_source: str = param(
        '/joint_states',
        'Bag topic (sensor_msgs/JointState) the reference is built from.',
        topic=True,
    )
    reference_inputs: str = param(
        'controller',
        'How the reference is built from the recorded joint states: controller = recorded q, '
        "v smoothed at reference_smoothing_hz and a differentiated from it (a controller's "
        'smooth reference, what models are fitted and scored on); study = q and v low-passed '
        "with the robot label cut-offs (the study's inputs); recorded = q and v as recorded.",
        choices=('controller', 'study', 'recorded'),
    )
    reference_smoothing_hz: float = param(
        0.0,
        'Velocity smoothing of the controller reference [Hz] (zero-phase Butterworth), above '
        "the robot config's label cut-offs and below Nyquist; 0 = its input_smoothing_hz.",
        low=0.0,
    )
    qos_depth: int = param(
        100, 'Publisher queue depth [messages] (KEEP_LAST).', low=1, high=MAX_QUEUE_DEPTH
    )
    wait_for_subscribers: int = param(
        0,
        'Before playing, wait until the published topics (bag topics, reference and /clock) '
        'have at least this many subscriptions in all, e.g. 3 for a recorder of two topics and '
        'one predictor, plus one per use_sim_time node (0 = start at once).',
        low=0,
        high=10_000,
    )
    wait_timeout_s: float = param(
        30.0,
        'Give up waiting for subscribers after this long and play anyway [s].',
        low=0.0,
        high=MAX_SECONDS,
        low_open=True,
    )
    exit_when_done: bool = param(True, 'Shut the node down after the last cycle (unless loop).')
    diagnostics_period_s: float = param(
        1.0,
        'Period of the timing report on /diagnostics [s], from 0.05 s (20 '
        'reports a second) to an hour.',
        read_only=False,
        low=MIN_PERIOD_S,
        high=MAX_PERIOD_S,
    )
    executor: str = param(
        'single_threaded', 'rclpy executor that runs the callbacks.', choices=EXECUTORS
    )

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        if not self.bag:
            raise ConfigError('bag is required: the bag folder to play')
        check_schema(self)
        if not self.topics and self.reference_mode == 'none':
            raise ConfigError('nothing to publish: topics is empty and reference_mode is none')
        refuse_shared_topics(self)

    def topic_checks(self) -> TopicChecks:
        """Groups of (topic by parameter, the node's own topics) no two of which may meet.

        A bag's /diagnostics may be played beside the replay's own reports (one type), the
        reference never (a trajectory or joint state there would clash with them); a bag's
        /clock may not while the replay publishes its own.
        """
        named = {f'topics[{k}]': topic for k, topic in enumerate(self.topics)}
        own = {'/clock': 'clock (publish_clock)'} if self.publish_clock else {}
        if self.reference_mode == 'none':
            return [(named, own)]
        named['reference_topic'] = self.reference_topic
        return [(named, own), ({'reference_topic': self.reference_topic}, DIAGNOSTICS)]


@dataclass(frozen=True)
class PredictorNodeConfig:
    """Parameters of the predictor node."""

    artifact: str = param('', 'Model artifact folder (model.json + weights). Required.')
    robot_config: str = param(
        '',
        'Robot config YAML the artifact was trained for (joints, limits, IPO period). Empty: '
        'the package config/mabi_max100.yaml.',
    )
    input_type: str = param(
        'trajectory',
        'Reference message type: trajectory = trajectory_msgs/JointTrajectory (first point; '
        'accelerations used when present), joint_state = sensor_msgs/JointState (q, v; '
        'accelerations estimated causally).',
        choices=('trajectory', 'joint_state'),
    )
    input_topic: str = param('reference', 'Topic of the reference.', topic=True)
    input_depth: int = param(
        10,
        'Reference queue depth [messages] (KEEP_LAST); a few cycles suffice.',
        low=1,
        high=MAX_QUEUE_DEPTH,
    )
    output_topic: str = param(
        'tau_u',
        'sensor_msgs/JointState output: names in the artifact order, effort = tau_u [N*m, '
        'joint side], stamp = the input stamp.',
        topic=True,
    )
    output_depth: int = param(
        10,
        'tau_u and command queue depth [messages] (KEEP_LAST); 10 matches ros2_control. A '
        'reliable consumer that stalls longer than this many cycles loses the oldest.',
        low=1,
        high=MAX_QUEUE_DEPTH,
    )
    command_topic: str = param(
        '',
        'Also publish tau_u [N*m] as std_msgs/Float64MultiArray here (ros2_control forward '
        'command controller, e.g. /feed_forward_controller/commands); empty = off.',
        topic=True,
    )
    zero_command_on_stale: bool = param(
        True,
        'Ramp the command to zero when the reference goes stale (one IPO period of the slew '
        'limit per cycle) and back at that rate when it resumes: a forward command controller '
        'holds its last command, which would otherwise keep a stale torque.',
    )
    stale_after_cycles: int = param(
        5,
        'The reference is stale after this many IPO cycles without a valid sample [cycles]: '
        'the node stops publishing and says so; history is reset when it resumes.',
        low=1,
        high=10**6,  # PredictorConfig's bound on its counts
    )
    max_age_s: float = param(
        0.1,
        "Reject a sample that arrives later than this against the stream's own time base "
        '[s] (no shared clock needed), and one whose stamp leads it by more than one IPO period '
        '(or this, where shorter); 0 = off.',
        read_only=False,
        low=0.0,
        high=3600.0,
    )
    resync_after: int = param(
        5,
        'Samples refused for time in a row at which the last of them starts a new time base, '
        'with one warning (1: the first such sample does): a clock step on the sender never '
        'locks the stream out [samples].',
        read_only=False,
        low=1,
        high=10**6,
    )
    rearm_samples: int = param(
        2,
        'Consistent samples after one that fails the kinematic consistency gate before the '
        'model serves again; the hold output meanwhile [samples].',
        read_only=False,
        low=0,
        high=10**6,
    )
    consistency_scale: float = param(
        1.0,
        'Multiple of the kinematic consistency tolerances, on top of the robot config '
        'consistency_scale (1 = as derived from the limits and the IPO period) [-].',
        read_only=False,
        low=1e-3,
        high=1e3,
    )
    torque_rise_s: float = param(
        0.05,
        'Slew limit: tau_u changes by at most the torque limit per this time [s].',
        read_only=False,
        low=1e-4,
        high=60.0,
    )
    acceleration_cutoff_hz: float = param(
        0.0,
        'First-order low-pass of the causal acceleration estimate (backward difference of '
        'velocity) [Hz]; 0 = raw difference. Only for references without accelerations.',
        low=0.0,
    )
    torque_limit_scale: float = param(
        1.0,
        'Clamp tau_u to this share of the robot torque limits [-], from 1e-6 (practically '
        'zero) to 1.',
        read_only=False,
        low=MIN_TORQUE_LIMIT_SCALE,
        high=1.0,
    )
    range_margin: float = param(
        0.1,
        'Margin beyond the training range, as a share of its half range on each side [-]: '
        'out_of_range acts beyond it; fallback blends the physics prior in across it.',
        read_only=False,
        low=0.0,
        high=1e3,
    )
    out_of_range: str = param(
        'auto',
        'Inputs outside the training range: fallback (publish the physics prior, blended in '
        'across the margin), warn (count, log, still publish the model), reject (publish '
        'nothing), auto (fallback for models with a network, warn for physics models).',
        read_only=False,
        choices=('auto', 'fallback', 'warn', 'reject'),
    )
    fallback_artifact: str = param(
        '',
        'Physics artifact (rnea_id, rnea_effects, rnea_lq) for fallback; empty = the rnea_id '
        "beside the model in its run, else the model's own physics part, else the nominal model.",
    )
    adaptation: str = param(
        'off',
        'Online adaptation to drift: rls = a Coulomb level, a viscous coefficient and an offset '
        'per joint added to the model, learnt by recursive least squares from the measured '
        'currents on measured_topic (a motor-target model only); rls_inertia = that and a '
        "change of the robot's base inertial parameters (a tool or payload change); off = the "
        'model as fitted. The adapted values are on /diagnostics and saved beside the artifact '
        'on shutdown.',
        choices=('off', 'rls', 'rls_inertia'),
    )
    adaptation_time_constant_s: float = param(
        60.0,
        'Memory of the adaptation (its forgetting factor) [s]; at least 0.1 s (ten IPO periods '
        'and more).',
        low=0.1,
        high=MAX_SECONDS,
    )
    measured_topic: str = param(
        '/motor_currents',
        'sensor_msgs/JointState whose effort holds the measured motor currents [A], stamped '
        'like the reference they answer: what adaptation learns from.',
        topic=True,
    )
    torch_threads: int = param(
        1,
        'torch intra-op and inter-op threads, and numpy OpenBLAS threads [threads].',
        low=1,
        high=MAX_THREADS,
    )
    inference: str = param(
        'numpy',
        'Model evaluation per sample: numpy = the float64 one-sample path built from the '
        'fitted weights (equal to torch up to float32 rounding, several times faster), '
        'torch = the model predict().',
        choices=('numpy', 'torch'),
    )
    log_throttle_s: float = param(
        1.0,
        'Minimum interval between repeated warnings and errors [s].',
        read_only=False,
        low=0.0,
        high=MAX_SECONDS,
        low_open=True,
    )
    stale_log_period_s: float = param(
        60.0,
        'A stale reference is logged once when it goes stale, then every this many seconds '
        'while it lasts (it is on /diagnostics throughout), at least 1 s; 0 = once [s].',
        read_only=False,
        low=0.0,
        high=MAX_SECONDS,
        zero_or_at_least=(MIN_LOG_PERIOD_S, 'once', 's'),  # a line per watchdog tick otherwise
    )
    latency_window: int = param(
        4096,
        'Samples kept for the latency statistics on /diagnostics [samples].',
        low=1,
        high=10**7,
    )
    diagnostics_period_s: float = param(
        1.0,
        'Period of the report on /diagnostics [s], from 0.05 s (20 reports a second) to an hour.',
        read_only=False,
        low=MIN_PERIOD_S,
        high=MAX_PERIOD_S,
    )
    executor: str = param(
        'events',
        'rclpy executor that runs the callbacks: events (C++, about half the per-sample '
        'overhead; latency is then measured from the callback start) or single_threaded '
        '(latency from the middleware receive timestamp).',
        choices=EXECUTORS,
    )

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        if not self.artifact:
            raise ConfigError('artifact is required: the model artifact folder')
        check_schema(self)
        refuse_shared_topics(self)

    def topic_checks(self) -> TopicChecks:
        """Groups of (topic by parameter, the node's own topics) no two of which may meet."""
        named = {'input_topic': self.input_topic, 'output_topic': self.output_topic}
        if self.command_topic:
            named['command_topic'] = self.command_topic
        if self.adaptation != 'off':
            named['measured_topic'] = self.measured_topic
        return [(named, DIAGNOSTICS)]


# -- files ----------------------------------------------------------------------------------------
def resolve_robot_config(value: str) -> Path:
    """The robot config file a node uses: ``value``, or the package's default one.

    Raises:
        ConfigError: the file does not exist.
    """
    if value:
        path = Path(value).expanduser()
        kind = not_a_file(path)
        # A FIFO is read as it comes (``robot_config:=<(...)``); read_capped refuses devices.
        if kind is not None and not kind.startswith('a FIFO'):
            raise ConfigError(f'robot_config: {path}: {kind}, not a robot config file')
        return path
    candidates = [Path(__file__).resolve().parents[2] / 'config' / DEFAULT_ROBOT_CONFIG]
    try:
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory(PACKAGE))
        candidates.insert(0, share / 'config' / DEFAULT_ROBOT_CONFIG)
    except (ImportError, LookupError, OSError, ValueError):
        pass  # not installed with colcon: the source checkout's config/ is the fallback
    for path in candidates:
        if path.is_file():
            return path
    raise ConfigError(
        f'robot_config is empty and the default {DEFAULT_ROBOT_CONFIG} was not found in '
        f'{[str(p) for p in candidates]}; set robot_config'
    )


def guard_config(config: PredictorNodeConfig, robot: RobotConfig) -> GuardConfig:
    """The core's guard settings from the node parameters and the robot's IPO period."""
    return GuardConfig(
        period_s=robot.ipo_period_s,
        stale_after_cycles=config.stale_after_cycles,
        max_age_s=config.max_age_s,
        resync_after=config.resync_after,
        rearm_samples=config.rearm_samples,
        consistency_scale=config.consistency_scale * robot.consistency_scale,
        torque_rise_s=config.torque_rise_s,
        acceleration_cutoff_hz=config.acceleration_cutoff_hz,
        torque_limit_scale=config.torque_limit_scale,
        range_margin=config.range_margin,
        out_of_range=cast(OutOfRangeAction, config.out_of_range),  # checked by the schema
    )
