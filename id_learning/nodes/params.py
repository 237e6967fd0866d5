"""The nodes' parameters: one frozen dataclass per node, declared to ROS from its fields.

Each field carries its ROS description (with units), whether it is read-only at runtime, and its
allowed values; ``__post_init__`` checks ranges and names the key. A node declares every field
(``declare_parameters``), reads one validated snapshot (``read_snapshot``) and, for the fields
that may change at runtime, validates a change by building a new snapshot before accepting it.

``config/nodes.yaml`` holds all three nodes' parameters in the ROS 2 parameter-file format;
``load_node_config`` reads it without ROS (and rejects unknown keys), for tests and tools.

This module imports rclpy only inside the functions that talk to a node.
"""

from __future__ import annotations

import dataclasses
import datetime
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, get_type_hints

from id_learning.config_io import load_yaml_mapping
from id_learning.errors import ConfigError

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = [
    'EXECUTORS',
    'PredictorNodeConfig',
    'RecorderConfig',
    'ReplayConfig',
    'config_from_mapping',
    'declare_parameters',
    'load_node_config',
    'read_snapshot',
    'resolve_robot_config',
    'validate_change',
]

PACKAGE = 'id_learning'
DEFAULT_ROBOT_CONFIG = 'mabi_max100.yaml'
EXECUTORS = ('single_threaded', 'events')
JOINT_STATE = 'sensor_msgs/msg/JointState'
_T = TypeVar('_T')


def param(
    default: Any,
    description: str,
    *,
    read_only: bool = True,
    choices: tuple[str, ...] | None = None,
) -> Any:
    """A dataclass field with the metadata of a ROS parameter."""
    if choices:
        description = f'{description} One of {list(choices)}.'
    return field(
        default=default,
        metadata={'description': description, 'read_only': read_only, 'choices': choices},
    )


def _check_choices(config: object) -> None:
    for item in dataclasses.fields(config):  # type: ignore[arg-type]
        choices = item.metadata.get('choices')
        value = getattr(config, item.name)
        if choices and value not in choices:
            raise ConfigError(f'{item.name} must be one of {list(choices)}, got {value!r}')


def _positive(config: object, *names: str, allow_zero: bool = False) -> None:
    for name in names:
        value = getattr(config, name)
        if value < 0 or (value == 0 and not allow_zero):
            relation = '>= 0 (0 = off)' if allow_zero else '> 0'
            raise ConfigError(f'{name} must be {relation}, got {value!r}')


# -- the three nodes ------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecorderConfig:
    """Parameters of the recorder node."""

    output: str = param(
        '',
        'Bag folder to write (rosbag2, MCAP storage). Empty: recordings/<UTC date-time> in '
        'the working directory.',
    )
    overwrite: bool = param(False, 'Replace an existing bag folder at output.')
    topics: tuple[str, ...] = param(
        ('/joint_states', '/motor_currents'), 'Topics to record (the bag contract).'
    )
    msg_types: tuple[str, ...] = param(
        (JOINT_STATE, JOINT_STATE), 'Message type of each topic, as pkg/msg/Type.'
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
    )
    flush_period_s: float = param(
        0.25,
        'Period of the flush that ends the MCAP chunk and pushes it to the file [s]; bounds what '
        'a SIGKILL can lose. At most 0.5 s.',
    )
    chunk_kib: int = param(
        512, 'MCAP chunk size [KiB] at which a chunk is closed between flushes.'
    )
    split_duration_s: float = param(
        0.0, 'Start a new .mcap file after this much log time [s]; 0 = no split by duration.'
    )
    split_size_mib: float = param(
        0.0, 'Start a new .mcap file at this file size [MiB]; 0 = no split by size.'
    )
    diagnostics_period_s: float = param(
        1.0, 'Period of the counts published on /diagnostics [s].', read_only=False
    )
    executor: str = param(
        'single_threaded', 'rclpy executor that runs the callbacks.', choices=EXECUTORS
    )

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        _check_choices(self)
        if not self.topics or len(self.topics) != len(self.msg_types):
            raise ConfigError(
                f'topics and msg_types need one entry per topic, got {list(self.topics)} and '
                f'{list(self.msg_types)}'
            )
        if len(set(self.topics)) != len(self.topics):
            raise ConfigError(f'topics lists a topic twice: {list(self.topics)}')
        for msg_type in self.msg_types:
            if msg_type.count('/') != 2:
                raise ConfigError(f'msg_types: expected pkg/msg/Type, got {msg_type!r}')
        _positive(self, 'qos_depth', 'chunk_kib', 'diagnostics_period_s')
        if not 0 < self.flush_period_s <= 0.5:
            raise ConfigError(f'flush_period_s must be in (0, 0.5] s, got {self.flush_period_s}')
        _positive(self, 'split_duration_s', 'split_size_mib', allow_zero=True)

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
    )
    robot_config: str = param(
        '',
        'Robot config YAML (joints, IPO period, label and input cut-offs). Empty: the '
        'package config/mabi_max100.yaml.',
    )
    rate: float = param(1.0, 'Playback speed factor [-]: 2.0 plays twice as fast.')
    loop: bool = param(False, 'Start again from the start offset at the end.')
    start_offset_s: float = param(0.0, 'Skip this much of the bag from its first sample [s].')
    duration_s: float = param(0.0, 'Play this much of the bag [s]; 0 = to the end.')
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
    reference_topic: str = param('reference', 'Topic of the reference.')
    reference_source: str = param(
        '/joint_states', 'Bag topic (sensor_msgs/JointState) the reference is built from.'
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
        'Velocity smoothing of the controller reference [Hz] (zero-phase Butterworth); '
        '0 = the robot config input_smoothing_hz.',
    )
    qos_depth: int = param(100, 'Publisher queue depth [messages] (KEEP_LAST).')
    wait_for_subscribers: int = param(
        0,
        'Before playing, wait until the published topics (bag topics, reference and /clock) '
        'have at least this many subscriptions in all, e.g. 3 for a recorder of two topics and '
        'one predictor, plus one per use_sim_time node (0 = start at once).',
    )
    wait_timeout_s: float = param(
        30.0, 'Give up waiting for subscribers after this long and play anyway [s].'
    )
    exit_when_done: bool = param(True, 'Shut the node down after the last cycle (unless loop).')
    diagnostics_period_s: float = param(
        1.0, 'Period of the timing report on /diagnostics [s].', read_only=False
    )
    executor: str = param(
        'single_threaded', 'rclpy executor that runs the callbacks.', choices=EXECUTORS
    )

    def __post_init__(self) -> None:
        """Check ranges, naming the key."""
        _check_choices(self)
        if not self.bag:
            raise ConfigError('bag is required: the bag folder to play')
        if not 0 < self.rate <= 100:
            raise ConfigError(f'rate must be in (0, 100], got {self.rate}')
        _positive(
            self,
            'start_offset_s',
            'duration_s',
            'wait_for_subscribers',
            'reference_smoothing_hz',
            allow_zero=True,
        )
        _positive(self, 'qos_depth', 'wait_timeout_s', 'diagnostics_period_s')
        if not self.topics and self.reference_mode == 'none':
            raise ConfigError('nothing to publish: topics is empty and reference_mode is none')


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
    input_topic: str = param('reference', 'Topic of the reference.')
    input_depth: int = param(
        10, 'Reference queue depth [messages] (KEEP_LAST); a few cycles suffice.'
    )
    output_topic: str = param(
        'tau_u',
        'sensor_msgs/JointState output: names in the artifact order, effort = tau_u [N*m, '
        'joint side], stamp = the input stamp.',
    )
    command_topic: str = param(
        '',
        'Also publish tau_u [N*m] as std_msgs/Float64MultiArray here (ros2_control forward '
        'command controller, e.g. /feed_forward_controller/commands); empty = off.',
    )
    zero_command_on_stale: bool = param(
        True,
        'Publish one zero command when the reference goes stale: a forward command controller '
        'holds its last command, which would otherwise keep a stale torque.',
    )
    stale_after_cycles: int = param(
        5,
        'The reference is stale after this many IPO cycles without a valid sample [cycles]: '
        'the node stops publishing and says so; history is reset when it resumes.',
    )
    max_age_s: float = param(
        0.0,
        'Reject samples whose stamp is older than this against the node clock [s]; 0 = off. '
        'Needs a shared time base (PTP, or use_sim_time with the replay /clock).',
        read_only=False,
    )
    acceleration_cutoff_hz: float = param(
        0.0,
        'First-order low-pass of the causal acceleration estimate (backward difference of '
        'velocity) [Hz]; 0 = raw difference. Only for references without accelerations.',
    )
    torque_limit_scale: float = param(
        1.0,
        'Clamp tau_u to this share of the robot torque limits [-], in (0, 1].',
        read_only=False,
    )
    range_margin: float = param(
        0.1,
        'Margin beyond the training range, as a share of its half range on each side [-]: '
        'out_of_range acts beyond it; fallback blends the physics prior in across it.',
        read_only=False,
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
        60.0, 'Memory of the adaptation (its forgetting factor) [s].'
    )
    measured_topic: str = param(
        '/motor_currents',
        'sensor_msgs/JointState whose effort holds the measured motor currents [A], stamped '
        'like the reference they answer: what adaptation learns from.',
    )
    torch_threads: int = param(
        1, 'torch intra-op and inter-op threads, and numpy OpenBLAS threads [threads].'
    )
    inference: str = param(
        'numpy',
        'Model evaluation per sample: numpy = the float64 one-sample path built from the '
        'fitted weights (equal to torch up to float32 rounding, several times faster), '
        'torch = the model predict().',
        choices=('numpy', 'torch'),
    )
    log_throttle_s: float = param(
        1.0, 'Minimum interval between repeated warnings and errors [s].', read_only=False
    )
    stale_log_period_s: float = param(
        60.0,
        'A stale reference is logged once when it goes stale, then every this many seconds '
        'while it lasts (it is on /diagnostics throughout); 0 = once [s].',
        read_only=False,
    )
    latency_window: int = param(
        4096, 'Samples kept for the latency statistics on /diagnostics [samples].'
    )
    diagnostics_period_s: float = param(
        1.0, 'Period of the report on /diagnostics [s].', read_only=False
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
        _check_choices(self)
        if not self.artifact:
            raise ConfigError('artifact is required: the model artifact folder')
        _positive(
            self,
            'input_depth',
            'stale_after_cycles',
            'torch_threads',
            'log_throttle_s',
            'latency_window',
            'diagnostics_period_s',
            'adaptation_time_constant_s',
        )
        if self.adaptation_time_constant_s < 0.1:
            raise ConfigError(
                'adaptation_time_constant_s must be at least 0.1 s (ten IPO periods and more), '
                f'got {self.adaptation_time_constant_s}'
            )
        _positive(
            self,
            'max_age_s',
            'acceleration_cutoff_hz',
            'range_margin',
            'stale_log_period_s',
            allow_zero=True,
        )
        if not 0 < self.torque_limit_scale <= 1:
            raise ConfigError(
                f'torque_limit_scale must be in (0, 1], got {self.torque_limit_scale}'
            )


# -- files ----------------------------------------------------------------------------------------
def resolve_robot_config(value: str) -> Path:
    """The robot config file a node uses: ``value``, or the package's default one.

    Raises:
        ConfigError: the file does not exist.
    """
    if value:
        path = Path(value).expanduser()
        if not path.is_file():
            raise ConfigError(f'robot_config: no such file {path}')
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


def _field_types(cls: type) -> dict[str, Any]:
    return get_type_hints(cls)


def _coerce(name: str, kind: Any, value: Any) -> Any:
    """A parameter value as the dataclass field's type, or ConfigError."""
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind == tuple[str, ...]:
        if isinstance(value, (list, tuple)) and all(isinstance(item, str) for item in value):
            return tuple(value)
    elif isinstance(value, kind) and not (kind is int and isinstance(value, bool)):
        return value
    raise ConfigError(f'{name}: expected {getattr(kind, "__name__", kind)}, got {value!r}')


def config_from_mapping(cls: type[_T], values: Mapping[str, Any], where: str) -> _T:
    """Build a node config from parameter values; unknown keys and wrong types name the key.

    Raises:
        ConfigError: unknown key, wrong type or a value out of range.
    """
    types = _field_types(cls)
    unknown = sorted(set(values) - set(types))
    if unknown:
        raise ConfigError(f'{where}: unknown parameter(s) {unknown}; known: {sorted(types)}')
    try:
        return cls(**{name: _coerce(name, types[name], value) for name, value in values.items()})
    except ConfigError as err:
        raise ConfigError(f'{where}: {err}') from None


def load_node_config(path: Path | str, node: str, cls: type[_T]) -> _T:
    """Read one node's ``ros__parameters`` from a ROS 2 parameter file.

    Raises:
        ConfigError: the file or the node's section is missing or invalid.
    """
    path = Path(path)
    data = load_yaml_mapping(path)
    section = data.get(node) or data.get(f'/{node}') or data.get('/**')
    if not isinstance(section, Mapping) or not isinstance(section.get('ros__parameters'), Mapping):
        raise ConfigError(f'{path}: no {node}: ros__parameters: section')
    values = dict(section['ros__parameters'])
    values = {key: value for key, value in values.items() if key != 'use_sim_time'}
    return config_from_mapping(cls, values, f'{path}: {node}')


# -- ROS ----------------------------------------------------------------------------------------
def declare_parameters(node: Node, cls: type) -> None:
    """Declare every field of a node config as a parameter with its description and default."""
    from rcl_interfaces.msg import ParameterDescriptor, ParameterType

    types = _field_types(cls)
    ros_types = {
        bool: ParameterType.PARAMETER_BOOL,
        int: ParameterType.PARAMETER_INTEGER,
        float: ParameterType.PARAMETER_DOUBLE,
        str: ParameterType.PARAMETER_STRING,
        tuple[str, ...]: ParameterType.PARAMETER_STRING_ARRAY,
    }
    for item in dataclasses.fields(cls):
        kind = types[item.name]
        default = item.default
        descriptor = ParameterDescriptor(
            name=item.name,
            type=ros_types[kind],
            description=item.metadata['description'],
            read_only=item.metadata['read_only'],
            # A YAML '1' for a float parameter is an integer: accept it and convert on reading.
            dynamic_typing=kind is float,
        )
        if item.metadata.get('choices'):
            descriptor.additional_constraints = f'one of {list(item.metadata["choices"])}'
        node.declare_parameter(
            item.name, list(default) if isinstance(default, tuple) else default, descriptor
        )


def read_snapshot(node: Node, cls: type[_T]) -> _T:
    """Read every declared field of a node config into one validated snapshot.

    Raises:
        ConfigError: a value has the wrong type or is out of range (names the parameter).
    """
    values = {
        item.name: node.get_parameter(item.name).value
        for item in dataclasses.fields(cls)  # type: ignore[arg-type]
    }
    return config_from_mapping(cls, values, f'node {node.get_name()}')


def validate_change(current: _T, changes: Mapping[str, Any]) -> tuple[_T | None, str]:
    """A new snapshot with ``changes`` applied, or None and the reason to reject them."""
    types = _field_types(type(current))
    metadata = {item.name: item.metadata for item in dataclasses.fields(current)}  # type: ignore[arg-type]
    updates = {}
    for name, value in changes.items():
        if name not in metadata:
            continue  # not ours (use_sim_time and the like)
        if metadata[name]['read_only']:
            return None, f'{name} is read-only at runtime'
        try:
            updates[name] = _coerce(name, types[name], value)
        except ConfigError as err:
            return None, str(err)
    try:
        return dataclasses.replace(current, **updates), ''  # type: ignore[type-var]
    except ConfigError as err:
        return None, str(err)
