"""The digital twin: a robot that differs from its nominal model by named effects.

It is recorded as the real robot would be (quantised encoders, noisy and quantised currents,
optional delay).

``simulate`` is deterministic: the same config and seeds give the same samples and the same bag.
``seed`` draws the recording (excitation, noise), ``robot_seed`` (default: ``seed``) the robot's
hidden parameters, so one robot can be recorded many times.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from id_learning.config_io import (
    check_keys,
    config_base,
    finite_number,
    float_vector,
    load_yaml_mapping,
)
from id_learning.dataset.recording import Recording
from id_learning.errors import ConfigError
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.record.excitation import (
    ExcitationConfig,
    ExcitationTrajectory,
    design_excitation,
    home_pose,
)
from id_learning.robot.config import RobotConfig, load_robot_config
from id_learning.robot.drives import (
    current_from_motor_torque,
    rotor_inertia_torque,
    torque_per_ampere,
)
from id_learning.twin.bounds import (
    check_drawn_masses,
    check_duration,
    check_excitation,
    check_measurement,
)
from id_learning.twin.effects import (
    CoggingEffect,
    CoulombFriction,
    EffectSet,
    GravitySpring,
    InertialParameterError,
    JointOffset,
    LoadDependentFriction,
    PayloadMass,
    RotorInertia,
    SignalDelay,
    StribeckFriction,
    TorqueConstantScale,
    TorqueOffset,
    ViscousFriction,
    effects_from_dict,
)
from id_learning.twin.result import TwinResult, rms_figures

__all__ = [
    'GROUND_TRUTH_ARRAYS',
    'GROUND_TRUTH_JSON',
    'MeasurementConfig',
    'TwinConfig',
    'TwinResult',
    'friction_and_cogging',
    'load_twin_config',
    'random_streams',
    'simulate',
    'true_dynamics',
]

_LOG = logging.getLogger(__name__)
GROUND_TRUTH_JSON = 'ground_truth.json'
GROUND_TRUTH_ARRAYS = 'ground_truth.npz'
TWIN_CONFIG_COPY = 'twin_config.yaml'
BLOCK = 4096  # samples per progress step


@dataclass(frozen=True, eq=False)
class MeasurementConfig:
    """Sensor models. Vectors have one value per joint.

    Attributes:
        current_noise_std_a: white noise on the motor currents [A].
        current_resolution_a: current quantisation step [A] (0: none).
        encoder_counts_per_motor_turn: motor encoder resolution [counts/turn] (0: none).
        velocity_noise_std: white noise on the drive's velocity [rad/s].
        joint_torque_noise_std: noise of joint torque sensors, when the robot has them [N*m].
    """

    current_noise_std_a: np.ndarray
    current_resolution_a: np.ndarray
    encoder_counts_per_motor_turn: int
    velocity_noise_std: np.ndarray
    joint_torque_noise_std: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """Plain representation for YAML/JSON."""
        return {
            key: value.tolist() if isinstance(value, np.ndarray) else value
            for key, value in self.__dict__.items()
        }


@dataclass(frozen=True, eq=False)
class TwinConfig:
    """Everything the twin needs: robot, effects, sensors, excitation, seed, and output options."""

    robot: RobotConfig
    robot_file: str
    seed: int
    start_time_ns: int
    excitation: ExcitationConfig
    effects: EffectSet
    measurement: MeasurementConfig
    joint_torque_sensors: bool = False
    robot_seed: int | None = None
    shift_start_s: float = 0.0
    raw: dict[str, Any] = field(default_factory=dict)
    where: str = 'twin config'  # the config file, named in errors

    @property
    def true_robot_seed(self) -> int:
        """The seed of the robot's hidden parameters: ``robot_seed``, else ``seed``."""
        return self.seed if self.robot_seed is None else self.robot_seed


_TOP = (
    'robot',
    'seed',
    'robot_seed',
    'start_time_ns',
    'excitation',
    'effects',
    'measurement',
    'joint_torque_sensors',
    'shift_start_s',
)
_MEASUREMENT = (
    'current_noise_std_a',
    'current_resolution_a',
    'encoder_counts_per_motor_turn',
    'velocity_noise_std',
    'joint_torque_noise_std',
)


def twin_config_from_dict(data: dict[str, Any], base_dir: Path, where: str) -> TwinConfig:
    """Build a validated TwinConfig from a parsed mapping; ``robot`` is relative to base_dir.

    Raises:
        ConfigError: unknown keys or bad values, naming them.
    """
    check_keys(data, _TOP, where, required=('robot',))
    robot_path = Path(str(data['robot']))
    if not robot_path.is_absolute():
        robot_path = base_dir / robot_path
    try:
        robot = load_robot_config(robot_path)
    except ConfigError as err:
        if robot_path.exists():
            raise
        raise ConfigError(f'{where}: robot {str(data["robot"])!r}: {err}') from err
    n = robot.n_joints
    excitation_data = data.get('excitation') or {}
    check_keys(
        excitation_data, list(ExcitationConfig.__dataclass_fields__), f'{where}: excitation'
    )
    excitation_data = check_excitation(
        excitation_data, robot.ipo_period_s, n, f'{where}: excitation'
    )
    if 'home' in excitation_data and excitation_data['home'] is not None:
        excitation_data = {
            **excitation_data,
            'home': tuple(
                float_vector(excitation_data['home'], f'{where}: excitation.home', n).tolist()
            ),
        }
    if excitation_data.get('file') is not None:  # relative to the config, as robot is
        if others := sorted(set(excitation_data) - {'file'}):
            raise ConfigError(
                f'{where}: excitation: file plays a designed excitation whole, so {others} '
                'would not apply: remove them (the design holds its own length and shape)'
            )
        designed = Path(str(excitation_data['file']))
        excitation_data['file'] = str(designed if designed.is_absolute() else base_dir / designed)
    try:
        excitation = ExcitationConfig(**excitation_data)
    except TypeError as err:
        raise ConfigError(f'{where}: excitation: {err}') from err
    if excitation.home is not None:  # named with the file here, not when simulated
        home_pose(excitation, robot.limits, robot.joints, f'{where}: excitation')
    m = data.get('measurement') or {}
    check_keys(m, _MEASUREMENT, f'{where}: measurement')
    counts = m.get('encoder_counts_per_motor_turn', 0)
    if not isinstance(counts, int) or isinstance(counts, bool) or counts < 0:
        raise ConfigError(
            f'{where}: measurement.encoder_counts_per_motor_turn must be an integer >= 0'
        )
    measurement = MeasurementConfig(
        current_noise_std_a=float_vector(
            m.get('current_noise_std_a', 0.0),
            f'{where}: measurement.current_noise_std_a',
            n,
            minimum=0.0,
        ),
        current_resolution_a=float_vector(
            m.get('current_resolution_a', 0.0),
            f'{where}: measurement.current_resolution_a',
            n,
            minimum=0.0,
        ),
        encoder_counts_per_motor_turn=counts,
        velocity_noise_std=float_vector(
            m.get('velocity_noise_std', 0.0),
            f'{where}: measurement.velocity_noise_std',
            n,
            minimum=0.0,
        ),
        joint_torque_noise_std=float_vector(
            m.get('joint_torque_noise_std', 0.0),
            f'{where}: measurement.joint_torque_noise_std',
            n,
            minimum=0.0,
        ),
    )
    check_measurement(vars(measurement), robot, where)
    seed = data.get('seed', 0)
    start = data.get('start_time_ns', 1_767_225_600_000_000_000)  # 2026-01-01T00:00:00Z
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ConfigError(f'{where}: seed must be a non-negative integer, got {seed!r}')
    robot_seed = data.get('robot_seed')
    if robot_seed is not None and (
        not isinstance(robot_seed, int) or isinstance(robot_seed, bool) or robot_seed < 0
    ):
        raise ConfigError(
            f'{where}: robot_seed must be a non-negative integer or null (= seed), '
            f'got {robot_seed!r}'
        )
    # Stamps are int64 nanoseconds: 2**62 ns (year 2116) leaves room for any duration.
    start = int(finite_number(start, f'{where}: start_time_ns', low=0, high=2**62, integer=True))
    shift_start = finite_number(data.get('shift_start_s', 0.0), f'{where}: shift_start_s', low=0)
    sensors = data.get('joint_torque_sensors', False)
    if not isinstance(sensors, bool):
        raise ConfigError(f'{where}: joint_torque_sensors must be true or false')
    return TwinConfig(
        robot=robot,
        robot_file=str(robot_path),
        seed=seed,
        start_time_ns=start,
        excitation=excitation,
        effects=effects_from_dict(data.get('effects'), robot.joints, f'{where}: effects'),
        measurement=measurement,
        joint_torque_sensors=sensors,
        robot_seed=robot_seed,
        shift_start_s=float(shift_start),
        raw=data,
        where=where,
    )


def load_twin_config(path: Path | str, overrides: dict[str, Any] | None = None) -> TwinConfig:
    """Read a twin config YAML (see config/twin_default.yaml), with optional top-level overrides.

    Raises:
        ConfigError: the file or a value in it is invalid.
    """
    path = Path(path)
    data = load_yaml_mapping(path)
    data.update(overrides or {})
    return twin_config_from_dict(data, config_base(path, data.get('robot')), str(path))


def true_dynamics(config: TwinConfig, rng: np.random.Generator) -> RigidBodyDynamics:
    """The twin's rigid-body model: URDF with inertial parameter errors and the payload."""
    dynamics = RigidBodyDynamics.from_config(config.robot)
    error = config.effects.get('inertial_parameter_error')
    assert isinstance(error, InertialParameterError)
    masses, coms = dynamics.body_masses_and_coms()
    mass_draw = rng.standard_normal(masses.shape)
    com_draw = rng.standard_normal(coms.shape)
    if error.enabled:
        drawn = masses * (1.0 + error.mass_rel_std * mass_draw)
        bodies = list(dynamics.model.names[1:])
        check_drawn_masses(masses, drawn, bodies, mass_rel_std=error.mass_rel_std,
                           robot_seed=config.true_robot_seed, where=config.where)  # fmt: skip
        dynamics = dynamics.with_masses_and_coms(drawn, coms + error.com_std_m * com_draw)
    payload = config.effects.get('payload_mass')
    assert isinstance(payload, PayloadMass)
    if payload.enabled and payload.mass_kg > 0:
        dynamics = dynamics.with_payload(
            config.robot.payload_frame,
            payload.mass_kg,
            np.array(payload.com_m),
            np.diag(payload.inertia_kgm2),
        )
    return dynamics


def _quantise(x: np.ndarray, step: np.ndarray | float) -> np.ndarray:
    step = np.asarray(step, dtype=float)
    safe = np.where(step > 0, step, 1.0)
    return np.where(step > 0, np.round(x / safe) * safe, x)


def _rigid_body_terms(
    dynamics: RigidBodyDynamics, q: np.ndarray, v: np.ndarray, a: np.ndarray, progress: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gravity, Coriolis and inertial (M a) torques, block by block with a progress bar."""
    gravity, coriolis, inertia = (np.empty_like(q) for _ in range(3))
    starts = range(0, len(q), BLOCK)
    for start in tqdm(
        starts, desc='twin dynamics', unit='block', disable=not progress, leave=False
    ):
        rows = slice(start, start + BLOCK)
        gravity[rows] = dynamics.gravity(q[rows])
        coriolis[rows] = dynamics.coriolis(q[rows], v[rows])
        inertia[rows] = np.einsum('bij,bj->bi', dynamics.mass_matrix(q[rows]), a[rows])
    return gravity, coriolis, inertia


def random_streams(seed: int) -> list[np.random.Generator]:
    """The twin's four random streams of a seed: excitation, robot, current noise, sensors."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]


def _trajectory(config: TwinConfig, rng: np.random.Generator) -> ExcitationTrajectory:
    """The excitation: the designed one of ``excitation.file``, else drawn from ``rng``."""
    robot, excitation = config.robot, config.excitation
    if excitation.file is not None:
        from id_learning.physics.excitation_design import load_design

        trajectory = load_design(Path(excitation.file), robot, 'excitation.file')
        check_duration(
            trajectory.duration_s, robot.ipo_period_s, robot.n_joints, 'excitation.file'
        )
        return trajectory
    check_duration(
        excitation.duration_s, robot.ipo_period_s, robot.n_joints, 'excitation.duration_s'
    )
    drawn = design_excitation(excitation, robot.limits, robot.ipo_period_s, rng)
    if note := excitation.duration_note(robot.ipo_period_s):
        _LOG.warning('%s', note)  # the rounding is said, not silent (see duration_note)
    return drawn


def simulate(config: TwinConfig, *, progress: bool = False) -> TwinResult:
    """Simulate an excitation run of the twin.

    Raises:
        ConfigError: a duration beyond the twin's bounds (``twin.bounds``), the excitation leaves
            the joint limits, or the true motor torque exceeds the config's torque limits
            (names joint and time).
    """
    robot, effects = config.robot, config.effects
    excitation_rng, _, noise_rng, sensor_rng = random_streams(config.seed)
    # The robot's hidden parameters come from their own seed, drawn as ``seed`` would draw them:
    # one robot, many recordings; robot_seed = seed reproduces the one-seed bags.
    parameter_rng = random_streams(config.true_robot_seed)[1]
    trajectory = _trajectory(config, excitation_rng)
    n_samples = round(trajectory.duration_s / robot.ipo_period_s) + 1
    t = np.arange(n_samples) * robot.ipo_period_s
    q, v, a = trajectory.evaluate(t)

    delay = effects.get('signal_delay')
    assert isinstance(delay, SignalDelay)
    delay_s = delay.delay_s if delay.enabled else 0.0
    # The currents measured at t belong to the motion at t - delay.
    qc, vc, ac = trajectory.evaluate(t - delay_s) if delay_s else (q, v, a)

    dynamics = true_dynamics(config, parameter_rng)
    gravity, coriolis, inertia = _rigid_body_terms(dynamics, qc, vc, ac, progress)
    components: dict[str, np.ndarray] = {
        'inertia': inertia,
        'coriolis': coriolis,
        'gravity': gravity,
    }

    spring = effects.get('gravity_spring')
    assert isinstance(spring, GravitySpring)
    spring_torque = np.zeros_like(qc)
    if spring.enabled:
        j = robot.joints.index(spring.joint)
        spring_torque[:, j] = spring.torque_on_joint(qc[:, j])
        components['gravity_spring'] = -spring_torque
    tau_joint = inertia + coriolis + gravity - spring_torque

    gear = robot.drives.gear_ratio
    rotor = effects.get('rotor_inertia')
    assert isinstance(rotor, RotorInertia)
    rotor_inertia = robot.drives.rotor_inertia * (rotor.scale if rotor.enabled else 1.0)
    components['rotor_inertia'] = rotor_inertia_torque(ac, rotor_inertia, gear)

    shift_time = config.shift_start_s + t - delay_s
    components |= friction_and_cogging(effects, vc, qc, tau_joint, gear, shift_time_s=shift_time)

    scale_effect = effects.get('torque_constant_scale')
    assert isinstance(scale_effect, TorqueConstantScale)
    kt_scale = scale_effect.scale if scale_effect.enabled else np.ones(robot.n_joints)
    # tau_u from currents uses the datasheet k_t; the real one is kt_scale times larger.
    components = {name: value / kt_scale for name, value in components.items()}
    offset = effects.get('torque_offset')
    assert isinstance(offset, TorqueOffset)
    if offset.enabled:
        components['torque_offset'] = np.broadcast_to(offset.offset, qc.shape).copy()
    tau_u_clean = np.sum(list(components.values()), axis=0)
    _check_torque_limits(tau_u_clean * kt_scale, robot, t)

    m = config.measurement
    current = current_from_motor_torque(tau_u_clean, robot.drives)
    current = current + m.current_noise_std_a * noise_rng.standard_normal(current.shape)
    current = _quantise(current, m.current_resolution_a)

    joint_offset = effects.get('joint_offset')
    assert isinstance(joint_offset, JointOffset)
    q_measured = q - (joint_offset.offset if joint_offset.enabled else 0.0)
    if m.encoder_counts_per_motor_turn:
        q_measured = _quantise(q_measured, 2 * np.pi / (m.encoder_counts_per_motor_turn * gear))
    v_measured = v + m.velocity_noise_std * sensor_rng.standard_normal(v.shape)
    joint_torque = None
    if config.joint_torque_sensors:
        # A torque sensor at the gear output sees the motion at the sample time, without delay.
        tau_joint_now = (
            _link_torque(dynamics, spring, robot, (q, v, a), progress) if delay_s else tau_joint
        )
        noise = m.joint_torque_noise_std * sensor_rng.standard_normal(q.shape)
        joint_torque = tau_joint_now + noise

    stamps = config.start_time_ns + np.round(t * 1e9).astype(np.int64)
    recording = Recording(
        joints=robot.joints,
        stamps_ns=stamps,
        position=q_measured,
        velocity=v_measured,
        current=current,
        joint_torque=joint_torque,
        source=f'twin seed {config.seed}, robot seed {config.true_robot_seed}',
    )
    parameters = _ground_truth_parameters(config, dynamics, rotor_inertia, kt_scale, delay_s)
    parameters['excitation'] = trajectory.to_dict()
    parameters |= rms_figures(components, tau_u_clean)
    return TwinResult(recording, components, tau_u_clean, tau_joint, q, v, a, parameters)


def friction_and_cogging(
    effects: EffectSet,
    vc: np.ndarray,
    qc: np.ndarray,
    tau_joint: np.ndarray,
    gear: np.ndarray,
    *,
    shift_time_s: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """The enabled friction laws' and cogging's torques [N*m] on the delayed motion.

    ``shift_time_s`` (N,): each sample's time into the shift, for a friction that warms up.
    """
    components: dict[str, np.ndarray] = {}
    viscous, coulomb, stribeck, load = (
        effects.get(name)
        for name in (
            'viscous_friction',
            'coulomb_friction',
            'stribeck_friction',
            'load_dependent_friction',
        )
    )
    assert isinstance(viscous, ViscousFriction)
    assert isinstance(coulomb, CoulombFriction)
    assert isinstance(stribeck, StribeckFriction)
    assert isinstance(load, LoadDependentFriction)
    if viscous.enabled:
        components['viscous_friction'] = viscous.torque(vc, shift_time_s)
    if coulomb.enabled:
        components['coulomb_friction'] = coulomb.torque(vc, shift_time_s)
    if stribeck.enabled:
        components['stribeck_friction'] = stribeck.torque(vc)
    if load.enabled:
        components['load_dependent_friction'] = load.torque(vc, tau_joint)
    cogging = effects.get('cogging')
    assert isinstance(cogging, CoggingEffect)
    if cogging.enabled:
        components['cogging'] = cogging.torque(qc, gear)
    return components


def _link_torque(
    dynamics: RigidBodyDynamics,
    spring: GravitySpring,
    robot: RobotConfig,
    motion: tuple[np.ndarray, np.ndarray, np.ndarray],
    progress: bool,
) -> np.ndarray:
    """The torque at the gear output [N*m]: rigid body minus the balancer's help."""
    q, v, a = motion
    gravity, coriolis, inertia = _rigid_body_terms(dynamics, q, v, a, progress)
    spring_torque = np.zeros_like(q)
    if spring.enabled:
        j = robot.joints.index(spring.joint)
        spring_torque[:, j] = spring.torque_on_joint(q[:, j])
    out: np.ndarray = gravity + coriolis + inertia - spring_torque
    return out


def _check_torque_limits(tau_motor: np.ndarray, robot: RobotConfig, t: np.ndarray) -> None:
    over = np.abs(tau_motor) > robot.limits.torque
    if over.any():
        k, j = (int(x) for x in np.argwhere(over)[0])
        raise ConfigError(
            f'twin: the motor torque of {robot.joints[j]} reaches {tau_motor[k, j]:.1f} N*m at '
            f't = {t[k]:.3f} s, beyond its limit {robot.limits.torque[j]:.1f} N*m: slow the '
            'excitation down or reduce the effects'
        )


def _ground_truth_parameters(
    config: TwinConfig,
    dynamics: RigidBodyDynamics,
    rotor_inertia: np.ndarray,
    kt_scale: np.ndarray,
    delay_s: float,
) -> dict[str, Any]:
    robot, m = config.robot, config.measurement
    tau_per_amp = torque_per_ampere(robot.drives)
    masses, coms = dynamics.body_masses_and_coms()
    return {
        'robot': robot.name,
        'joints': list(robot.joints),
        'urdf_sha256': robot.urdf_sha256(),
        'seed': config.seed,
        'robot_seed': config.true_robot_seed,
        'ipo_period_s': robot.ipo_period_s,
        'effects_enabled': config.effects.enabled_names(),
        'effects': config.effects.to_dict(),
        'true': {
            'rotor_inertia_motor_side_kgm2': rotor_inertia.tolist(),
            'torque_constant_nm_per_a': (robot.drives.torque_constant * kt_scale).tolist(),
            'signal_delay_s': delay_s,
            'body_masses_kg': masses.tolist(),
            'body_coms_m': coms.tolist(),
            'inertial_parameters': dynamics.inertial_parameters().tolist(),
        },
        'noise': {
            **m.to_dict(),
            'current_noise_std_as_tau_u_nm': (m.current_noise_std_a * tau_per_amp).tolist(),
            'current_quantisation_std_as_tau_u_nm': (
                m.current_resolution_a / np.sqrt(12) * tau_per_amp
            ).tolist(),
        },
        'units': {'torque': 'N*m joint side', 'current': 'A', 'angle': 'rad', 'time': 's'},
    }
