"""Robot config: URDF, joint order, drives, limits, IPO period and filter cut-offs, from one YAML.

Units are SI throughout. Drive values on the motor side say so (docs/configuration.md, "Units
convention"): ``gear_ratio`` is motor turns per joint turn, ``torque_constant`` is in N*m/A at
the motor shaft, ``rotor_inertia`` in kg*m^2 at the motor shaft. Everything else is joint side.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.config_io import (
    check_keys,
    config_base,
    finite_number,
    float_vector,
    load_yaml_mapping,
    number_hint,
    range_problem,
    topic_name_problem,
)
from id_learning.errors import ConfigError
from id_learning.robot.urdf_checks import check_urdf
from id_learning.robot.urdf_location import resolve_urdf

__all__ = [
    'DriveConfig',
    'JointLimits',
    'RobotConfig',
    'TopicConfig',
    'how_robots_differ',
    'load_robot_config',
    'resolve_urdf',
]

# The reference study's per-axis cut-offs, used when a config gives none (6-axis robots only).
STUDY_CUTOFF_HZ = (1.2, 0.3, 0.3, 0.7, 0.5, 0.7)
#: Default smoothing of recorded velocities into model inputs [Hz]: far above the excitation's
#: band (the study's harmonics reach 0.12 Hz), far below the IPO rate's Nyquist frequency.
DEFAULT_INPUT_SMOOTHING_HZ = 10.0


@dataclass(frozen=True, eq=False)
class DriveConfig:
    """Per-joint drive train, in the units convention of docs/configuration.md.

    Attributes:
        gear_ratio: (n,) motor turns per joint turn [-].
        torque_constant: (n,) motor torque per motor current [N*m/A], motor side.
        rotor_inertia: (n,) rotor inertia [kg*m^2], motor side.
    """

    gear_ratio: np.ndarray
    torque_constant: np.ndarray
    rotor_inertia: np.ndarray


@dataclass(frozen=True, eq=False)
class JointLimits:
    """Joint-side limits: position [rad], velocity [rad/s], accel. [rad/s^2], torque [N*m]."""

    position_lower: np.ndarray
    position_upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    torque: np.ndarray

    def take(self, order: Sequence[int]) -> JointLimits:
        """The limits of the joints at ``order`` (indices into this joint order)."""
        index = np.asarray(order, dtype=int)
        return JointLimits(
            self.position_lower[index],
            self.position_upper[index],
            self.velocity[index],
            self.acceleration[index],
            self.torque[index],
        )


@dataclass(frozen=True)
class TopicConfig:
    """Topic names of the bag contract: full names, as a bag stores them.

    A robot config may write them relative (``joint_states``): they are read as a node in the
    root namespace resolves them (``/joint_states``).
    """

    joint_states: str = '/joint_states'
    motor_currents: str = '/motor_currents'


@dataclass(frozen=True, eq=False)
class RobotConfig:
    """Everything the package needs to know about one robot.

    Attributes:
        name: robot name, stored in bags' ground truth and model artifacts.
        urdf_path: absolute path of the URDF.
        joints: ordered actuated joint names; every array below follows this order.
        locked_joints: URDF joints held fixed at the given position [rad or m] (e.g. gripper
            fingers).
        drives: gear ratios, torque constants and rotor inertias.
        limits: joint-side limits.
        ipo_period_s: controller interpolation (IPO) cycle [s].
        lowpass_cutoff_hz: (n,) zero-phase low-pass cut-off of the torque labels per joint [Hz]
            (the study's label filter).
        input_smoothing_hz: (n,) zero-phase low-pass cut-off per joint [Hz] that turns recorded
            velocities into model inputs, as a controller's smooth reference would carry them:
            well above the motion's band and the label cut-offs, so the inputs keep the motion
            as it happened (accelerations are differentiated from the smoothed velocity).
        payload_frame: URDF frame at which a payload is attached.
        consistency_scale: a multiple of the kinematic consistency gate's tolerances
            (``dataset.consistency``) for this robot's signals: 1 as derived from the limits
            and the IPO period; more for a robot whose recorded velocities lag or are filtered.
        topics: topic names of the bag contract.
        source: the YAML file this was read from, if any.
    """

    name: str
    urdf_path: Path
    joints: tuple[str, ...]
    drives: DriveConfig
    limits: JointLimits
    ipo_period_s: float
    lowpass_cutoff_hz: np.ndarray
    input_smoothing_hz: np.ndarray
    payload_frame: str
    locked_joints: dict[str, float] = field(default_factory=dict)
    topics: TopicConfig = field(default_factory=TopicConfig)
    source: Path | None = None
    consistency_scale: float = 1.0

    @property
    def n_joints(self) -> int:
        """Number of actuated joints."""
        return len(self.joints)

    def urdf_sha256(self) -> str:
        """SHA-256 of the URDF file, to tie data and models to the exact robot description.

        Its line ends count as LF: a checkout with CRLF (git's ``core.autocrlf`` on Windows)
        is the same robot, and hashes as the LF file always did.
        """
        return hashlib.sha256(self.urdf_path.read_bytes().replace(b'\r\n', b'\n')).hexdigest()


_TOP_KEYS = (
    'name',
    'urdf',
    'joints',
    'locked_joints',
    'drives',
    'limits',
    'ipo_period_s',
    'lowpass_cutoff_hz',
    'input_smoothing_hz',
    'payload_frame',
    'topics',
    'consistency_scale',
)
_LIMIT_KEYS = ('position_lower', 'position_upper', 'velocity', 'acceleration', 'torque')


def robot_config_from_dict(data: dict[str, Any], base_dir: Path, where: str) -> RobotConfig:
    """Build a validated RobotConfig from a parsed YAML mapping.

    Raises:
        ConfigError: a key is unknown or missing, or a value is out of range (names key and value).
        RobotModelError: a URDF that cannot be the robot (``urdf_checks.check_urdf``): a link no
            rigid body can be, an axis of zero length, a driven joint that mimics another, no
            moving link with mass.
    """
    check_keys(
        data,
        _TOP_KEYS,
        where,
        required=('name', 'urdf', 'joints', 'drives', 'limits', 'ipo_period_s', 'payload_frame'),
    )
    joints = data['joints']
    if (
        not isinstance(joints, list)
        or not joints
        or not all(isinstance(name, str) and name for name in joints)
    ):
        raise ConfigError(
            f'{where}: joints: expected a non-empty list of joint names, got {joints!r}'
        )
    duplicates = sorted({name for name in joints if joints.count(name) > 1})
    if duplicates:
        raise ConfigError(f'{where}: joints: duplicate joint names {duplicates}')
    n = len(joints)

    drive = _drives(data['drives'], n, where)
    limits = _limits(data['limits'], joints, where)

    period = data['ipo_period_s']
    if range_problem(period, low=1e-5, high=1.0):  # a str or bool is no period either
        kind = type(period).__name__.replace('str', 'string')
        raise ConfigError(
            f'{where}: ipo_period_s must be in [1e-5, 1] s, got {period!r}'
            if isinstance(period, (int, float)) and not isinstance(period, bool)
            else f'{where}: ipo_period_s must be in [1e-5, 1] s and a number, not a {kind}: '
            f'got {period!r}{number_hint(period, "s")}'
        )
    cutoff, smoothing = _cutoffs(data, n, float(period), where)

    locked = data.get('locked_joints') or {}
    if not isinstance(locked, dict):
        raise ConfigError(f'{where}: locked_joints: expected a mapping joint name -> position')
    for joint, value in locked.items():
        if range_problem(value):
            text = ', a string, not a number' if isinstance(value, str) else ''
            raise ConfigError(
                f'{where}: locked_joints: expected a mapping joint name -> position [rad or m], '
                f'a finite number; {joint}: {value!r}{text}{number_hint(value, "rad or m")}'
            )
    overlap = sorted(set(locked) & set(joints))
    if overlap:
        raise ConfigError(f'{where}: locked_joints {overlap} are also listed in joints')

    topics_data = data.get('topics') or {}
    if not isinstance(topics_data, dict):
        raise ConfigError(f'{where}: topics: expected a mapping, got {topics_data!r}')
    check_keys(topics_data, ('joint_states', 'motor_currents'), f'{where}: topics')
    for key, topic in topics_data.items():
        problem = topic_name_problem(topic)
        if problem:
            raise ConfigError(f'{where}: topics.{key}: {topic!r} is no ROS topic name: {problem}')
        if '~' in topic or '{' in topic:
            raise ConfigError(
                f'{where}: topics.{key}: {topic!r} depends on a node name; a bag stores topics '
                "by their full names: write it as '/...'"
            )
    # A bag stores full names: a relative name is resolved as a node in the root namespace
    # resolves it (the recorder's default), 'joint_states' -> '/joint_states'.
    topics = TopicConfig(
        **{
            key: topic if topic.startswith('/') else f'/{topic}'
            for key, topic in topics_data.items()
        }
    )
    if topics.joint_states == topics.motor_currents:
        raise ConfigError(
            f'{where}: topics.joint_states and topics.motor_currents are both '
            f'{topics.joint_states!r}: the joint states and the motor currents are two topics'
        )

    name = data['name']
    if not isinstance(name, str) or not name:
        raise ConfigError(f'{where}: name must be a non-empty string')
    urdf_path = resolve_urdf(str(data['urdf']), base_dir, where)
    check_urdf(urdf_path, joints, locked, where)
    return RobotConfig(
        name=name,
        urdf_path=urdf_path,
        joints=tuple(joints),
        drives=drive,
        limits=limits,
        ipo_period_s=float(period),
        lowpass_cutoff_hz=cutoff,
        input_smoothing_hz=smoothing,
        payload_frame=str(data['payload_frame']),
        locked_joints={key: float(value) for key, value in locked.items()},
        topics=topics,
        consistency_scale=finite_number(
            data.get('consistency_scale', 1.0), f'{where}: consistency_scale', low=1e-3, high=1e3
        ),
    )


def _drives(drives: Any, n: int, where: str) -> DriveConfig:
    """The drives section: gear ratios, torque constants and rotor inertias per joint."""
    if not isinstance(drives, dict):
        raise ConfigError(f'{where}: drives: expected a mapping')
    check_keys(
        drives,
        ('gear_ratio', 'torque_constant', 'rotor_inertia'),
        f'{where}: drives',
        required=('gear_ratio', 'torque_constant', 'rotor_inertia'),
    )
    return DriveConfig(
        gear_ratio=float_vector(
            drives['gear_ratio'],
            f'{where}: drives.gear_ratio',
            n,
            minimum=0.0,
            exclusive_minimum=True,
        ),
        torque_constant=float_vector(
            drives['torque_constant'],
            f'{where}: drives.torque_constant',
            n,
            minimum=0.0,
            exclusive_minimum=True,
        ),
        rotor_inertia=float_vector(
            drives['rotor_inertia'], f'{where}: drives.rotor_inertia', n, minimum=0.0
        ),
    )


def _limits(limits_data: Any, joints: list[str], where: str) -> JointLimits:
    """The limits section; each position range must be non-empty."""
    n = len(joints)
    if not isinstance(limits_data, dict):
        raise ConfigError(f'{where}: limits: expected a mapping')
    check_keys(limits_data, _LIMIT_KEYS, f'{where}: limits', required=_LIMIT_KEYS)
    lower = float_vector(limits_data['position_lower'], f'{where}: limits.position_lower', n)
    upper = float_vector(limits_data['position_upper'], f'{where}: limits.position_upper', n)
    if np.any(lower >= upper):
        joint = joints[int(np.argmax(lower >= upper))]
        raise ConfigError(
            f'{where}: limits: position_lower must be below position_upper (joint {joint})'
        )
    return JointLimits(
        position_lower=lower,
        position_upper=upper,
        velocity=float_vector(
            limits_data['velocity'],
            f'{where}: limits.velocity',
            n,
            minimum=0.0,
            exclusive_minimum=True,
        ),
        acceleration=float_vector(
            limits_data['acceleration'],
            f'{where}: limits.acceleration',
            n,
            minimum=0.0,
            exclusive_minimum=True,
        ),
        torque=float_vector(
            limits_data['torque'],
            f'{where}: limits.torque',
            n,
            minimum=0.0,
            exclusive_minimum=True,
        ),
    )


def _cutoffs(
    data: dict[str, Any], n: int, period_s: float, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """The label filter's and the input smoothing's cut-offs [Hz], per joint, checked.

    Raises:
        ConfigError: a cut-off at or above the Nyquist frequency, label cut-offs missing for a
            robot without study defaults, or an input smoothing not above the label cut-off.
    """
    nyquist = 0.5 / period_s
    if 'lowpass_cutoff_hz' in data:
        cutoff = float_vector(
            data['lowpass_cutoff_hz'],
            f'{where}: lowpass_cutoff_hz',
            n,
            minimum=0.0,
            exclusive_minimum=True,
        )
    elif n == len(STUDY_CUTOFF_HZ):
        cutoff = float_vector(list(STUDY_CUTOFF_HZ), f'{where}: lowpass_cutoff_hz', n)
    else:
        raise ConfigError(f'{where}: lowpass_cutoff_hz is required for a {n}-joint robot')
    if np.any(cutoff >= nyquist):
        raise ConfigError(
            f'{where}: lowpass_cutoff_hz must be below the Nyquist frequency {nyquist:g} Hz, '
            f'got {cutoff.tolist()}'
        )
    # The default, or halfway between the label cut-off and Nyquist where that cut-off is higher.
    default = min(DEFAULT_INPUT_SMOOTHING_HZ, 0.4 * nyquist)
    default_vector = np.where(cutoff < default, default, 0.5 * (cutoff + nyquist)).tolist()
    smoothing = float_vector(
        data.get('input_smoothing_hz', default_vector),
        f'{where}: input_smoothing_hz',
        n,
        minimum=0.0,
        exclusive_minimum=True,
    )
    if np.any(smoothing >= nyquist):
        raise ConfigError(
            f'{where}: input_smoothing_hz must be below the Nyquist frequency {nyquist:g} Hz, '
            f'got {smoothing.tolist()}'
        )
    if np.any(smoothing <= cutoff):
        raise ConfigError(
            f'{where}: input_smoothing_hz {smoothing.tolist()} must lie above the label '
            f'cut-offs lowpass_cutoff_hz {cutoff.tolist()}: the inputs keep the motion the '
            'labels smear'
        )
    return cutoff, smoothing


def load_robot_config(path: Path | str) -> RobotConfig:
    """Read and validate a robot config YAML (see config/mabi_max100.yaml).

    Raises:
        ConfigError: the file or one of its values is invalid; the message names file and key.
    """
    path = Path(path)
    data = load_yaml_mapping(path)
    config = robot_config_from_dict(data, config_base(path, data.get('urdf')), str(path))
    return RobotConfig(**{**config.__dict__, 'source': path.resolve()})


def how_robots_differ(a: RobotConfig, b: RobotConfig) -> str:
    """What tells robot ``b`` from robot ``a`` by name and joints; '' when they agree.

    Names the name, the joints one has and the other lacks, or the same joints in another
    order, so that a refusal says more than two equal names.
    """
    out = []
    if a.name != b.name:
        out.append(f'robot {b.name!r}, not {a.name!r}')
    if a.joints != b.joints:
        if sorted(a.joints) == sorted(b.joints):
            out.append(
                f'the same joints in another order ({list(b.joints)}, not {list(a.joints)})'
            )
        else:
            lacks = [j for j in a.joints if j not in b.joints]
            extra = [j for j in b.joints if j not in a.joints]
            out.append(
                'other joints ('
                + '; '.join(
                    [*([f'lacks {lacks}'] if lacks else []), *([f'adds {extra}'] if extra else [])]
                )
                + ')'
            )
    return ', '.join(out)
