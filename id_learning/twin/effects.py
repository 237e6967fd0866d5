"""Physical effects that make the digital twin's robot differ from the nominal model.

Every effect has a stable name, shared with the diagnosis. Torques are joint side [N*m]; vectors
hold one value per joint in config order. The nominal model is the URDF's rigid-body dynamics plus
the config's drives (gear ratio, torque constant, datasheet rotor inertia); with every effect
disabled the twin's noise-free tau_u equals it exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np

from id_learning.config_io import check_keys, float_vector
from id_learning.errors import ConfigError
from id_learning.physics.effects import EFFECT_NAMES
from id_learning.physics.friction import (
    STRIBECK_SHAPES,
    coulomb,
    load_dependent,
    stribeck,
    viscous,
    warm_up,
)
from id_learning.robot.urdf_inertials import principal_moments_problem

__all__ = [
    'EFFECT_NAMES',
    'MAX_MASS_REL_STD',
    'CoggingEffect',
    'CoulombFriction',
    'Effect',
    'EffectSet',
    'GravitySpring',
    'InertialParameterError',
    'JointOffset',
    'LoadDependentFriction',
    'PayloadMass',
    'RotorInertia',
    'SignalDelay',
    'StribeckFriction',
    'TorqueConstantScale',
    'TorqueOffset',
    'ViscousFriction',
    'effects_from_dict',
    'non_positive_mass_chance',
]


@dataclass(frozen=True, eq=False)
class Effect:
    """Base of all effects: a name and whether it is switched on."""

    name: ClassVar[str] = ''
    vector_fields: ClassVar[tuple[str, ...]] = ()
    enabled: bool = False

    def to_dict(self) -> dict[str, Any]:
        """Plain-YAML/JSON representation (arrays as lists)."""
        out: dict[str, Any] = {}
        for item in fields(self):
            value = getattr(self, item.name)
            out[item.name] = value.tolist() if isinstance(value, np.ndarray) else value
        return out


@dataclass(frozen=True, eq=False)
class ViscousFriction(Effect):
    """tau = d * v, with d [N*m*s/rad] per joint, times the warm-up scale (``warm_up``)."""

    name: ClassVar[str] = 'viscous_friction'
    vector_fields: ClassVar[tuple[str, ...]] = ('coefficient',)
    coefficient: np.ndarray = field(default_factory=lambda: np.zeros(0))
    warm_scale: float = 1.0
    warm_up_s: float = 0.0

    def torque(self, v: np.ndarray, shift_time_s: np.ndarray | None = None) -> np.ndarray:
        """Friction torque (..., n) [N*m] at velocities v [rad/s] (N, n) and shift times (N,)."""
        scale = warm_up(self.warm_scale, self.warm_up_s, shift_time_s)
        (column,) = viscous(v)
        out: np.ndarray = self.coefficient * column * scale
        return out


@dataclass(frozen=True, eq=False)
class CoulombFriction(Effect):
    """tau = F_c * tanh(v / v_eps) times the warm-up scale (``warm_up``).

    F_c [N*m] per joint, smoothing velocity v_eps [rad/s].
    """

    name: ClassVar[str] = 'coulomb_friction'
    vector_fields: ClassVar[tuple[str, ...]] = ('level',)
    level: np.ndarray = field(default_factory=lambda: np.zeros(0))
    smoothing_velocity: float = 0.005
    warm_scale: float = 1.0
    warm_up_s: float = 0.0

    def torque(self, v: np.ndarray, shift_time_s: np.ndarray | None = None) -> np.ndarray:
        """Friction torque (..., n) [N*m] at velocities (N, n) and shift times (N,)."""
        scale = warm_up(self.warm_scale, self.warm_up_s, shift_time_s)
        out: np.ndarray = self.level * coulomb(v, self.smoothing_velocity) * scale
        return out


@dataclass(frozen=True, eq=False)
class StribeckFriction(Effect):
    """tau = F_s * hump(|v| / v_s) * tanh(v / v_eps): extra static friction at low speed.

    ``shape``: how the hump fades with speed (``physics.friction.STRIBECK_SHAPES``).
    """

    name: ClassVar[str] = 'stribeck_friction'
    vector_fields: ClassVar[tuple[str, ...]] = ('level', 'velocity')
    level: np.ndarray = field(default_factory=lambda: np.zeros(0))
    velocity: np.ndarray = field(default_factory=lambda: np.ones(0))
    smoothing_velocity: float = 0.005
    shape: str = 'gaussian'

    def torque(self, v: np.ndarray) -> np.ndarray:
        """Friction torque (..., n) [N*m]."""
        out: np.ndarray = self.level * stribeck(
            v, self.velocity, self.smoothing_velocity, self.shape
        )
        return out


@dataclass(frozen=True, eq=False)
class LoadDependentFriction(Effect):
    """tau = mu * |tau_load| * tanh(v / v_eps): gear friction grows with the transmitted torque."""

    name: ClassVar[str] = 'load_dependent_friction'
    vector_fields: ClassVar[tuple[str, ...]] = ('coefficient',)
    coefficient: np.ndarray = field(default_factory=lambda: np.zeros(0))
    smoothing_velocity: float = 0.005

    def torque(self, v: np.ndarray, load: np.ndarray) -> np.ndarray:
        """Friction torque (..., n) [N*m] for load torques ``load`` [N*m] through the gear."""
        out: np.ndarray = self.coefficient * load_dependent(v, load, self.smoothing_velocity)
        return out


@dataclass(frozen=True, eq=False)
class RotorInertia(Effect):
    """True rotor inertia = scale * datasheet value (brake and gear input stage add to it)."""

    name: ClassVar[str] = 'rotor_inertia'
    vector_fields: ClassVar[tuple[str, ...]] = ('scale',)
    scale: np.ndarray = field(default_factory=lambda: np.ones(0))


@dataclass(frozen=True, eq=False)
class GravitySpring(Effect):
    """Spring balancer on one joint (axis 2 of heavy arms).

    A spring between a point at distance ``arm_base_m`` from the joint axis on the preceding link
    and a point at ``arm_link_m`` on the moving link. Its length is
    l = sqrt(a^2 + b^2 - 2ab cos(q + phi)); the force is F = preload + stiffness * (l - |a - b|),
    and the torque it puts on the joint is -F * a * b * sin(q + phi) / l.
    """

    name: ClassVar[str] = 'gravity_spring'
    joint: str = 'joint_2'
    arm_base_m: float = 0.25
    arm_link_m: float = 0.40
    phase_rad: float = 0.0
    preload_n: float = 3000.0
    stiffness_n_per_m: float = 25000.0

    def torque_on_joint(self, q_joint: np.ndarray) -> np.ndarray:
        """Torque the spring applies to the joint [N*m] (helps the motor against gravity)."""
        a, b = self.arm_link_m, self.arm_base_m
        angle = np.asarray(q_joint) + self.phase_rad
        length = np.sqrt(a * a + b * b - 2 * a * b * np.cos(angle))
        force = self.preload_n + self.stiffness_n_per_m * (length - abs(a - b))
        return -force * a * b * np.sin(angle) / length


@dataclass(frozen=True, eq=False)
class PayloadMass(Effect):
    """A payload (spindle, tool) at the config's payload frame that the URDF does not contain."""

    name: ClassVar[str] = 'payload_mass'
    mass_kg: float = 0.0
    com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia_kgm2: tuple[float, float, float] = (0.0, 0.0, 0.0)  # principal moments about the COM


@dataclass(frozen=True, eq=False)
class JointOffset(Effect):
    """Encoder zero error: q_true = q_measured + offset [rad]."""

    name: ClassVar[str] = 'joint_offset'
    vector_fields: ClassVar[tuple[str, ...]] = ('offset',)
    offset: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True, eq=False)
class TorqueConstantScale(Effect):
    """True torque constant = scale * datasheet value; tau_u from currents is off by 1 / scale."""

    name: ClassVar[str] = 'torque_constant_scale'
    vector_fields: ClassVar[tuple[str, ...]] = ('scale',)
    scale: np.ndarray = field(default_factory=lambda: np.ones(0))


#: The longest signal delay a twin simulates [s]: 12.5 cycles of an 8 ms IPO. Real drive-bus
#: and current-filter latencies are a few milliseconds; the identification's first-order delay
#: term tau(t - d) ~ tau - d dtau/dt stays accurate only while d is small against the motion.
MAX_SIGNAL_DELAY_S = 0.1


@dataclass(frozen=True, eq=False)
class SignalDelay(Effect):
    """Currents lag the positions by ``delay_s`` [s] (drive bus and filter latency)."""

    name: ClassVar[str] = 'signal_delay'
    delay_s: float = 0.0


@dataclass(frozen=True, eq=False)
class CoggingEffect(Effect):
    """Motor cogging: amplitude [N*m, joint side] * sin(periods_per_motor_turn * N * q)."""

    name: ClassVar[str] = 'cogging'
    vector_fields: ClassVar[tuple[str, ...]] = ('amplitude',)
    amplitude: np.ndarray = field(default_factory=lambda: np.zeros(0))
    periods_per_motor_turn: int = 6

    def torque(self, q: np.ndarray, gear_ratio: np.ndarray) -> np.ndarray:
        """Cogging torque (..., n) [N*m] at joint positions q [rad]."""
        out: np.ndarray = self.amplitude * np.sin(self.periods_per_motor_turn * gear_ratio * q)
        return out


@dataclass(frozen=True, eq=False)
class TorqueOffset(Effect):
    """Current-sensor offset, expressed as a constant tau_u offset [N*m] per joint."""

    name: ClassVar[str] = 'torque_offset'
    vector_fields: ClassVar[tuple[str, ...]] = ('offset',)
    offset: np.ndarray = field(default_factory=lambda: np.zeros(0))


#: The largest relative mass error a twin draws: a scale 1 + mass_rel_std * N(0, 1) is <= 0
#: (a body of negative mass, which the dynamics take without a word) four standard deviations
#: down, for 3e-5 of the links; at 0.5 it would be 2 %. Manufacturer masses are a few % off.
MAX_MASS_REL_STD = 0.25


@dataclass(frozen=True, eq=False)
class InertialParameterError(Effect):
    """Real link masses and centres of mass differ from the URDF (manufacturer data).

    Masses are scaled by (1 + mass_rel_std * N(0, 1)), COMs moved by com_std_m * N(0, 1) per axis,
    drawn from the twin's seed; the rotational inertia about each COM is kept.
    """

    name: ClassVar[str] = 'inertial_parameter_error'
    mass_rel_std: float = 0.03
    com_std_m: float = 0.01


_CLASSES: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (
        ViscousFriction,
        CoulombFriction,
        StribeckFriction,
        LoadDependentFriction,
        RotorInertia,
        GravitySpring,
        PayloadMass,
        JointOffset,
        TorqueConstantScale,
        SignalDelay,
        CoggingEffect,
        TorqueOffset,
        InertialParameterError,
    )
}
assert tuple(_CLASSES) == EFFECT_NAMES


@dataclass(frozen=True, eq=False)
class EffectSet:
    """All effects of a twin, by name; disabled effects keep their parameters for reference."""

    effects: dict[str, Effect]

    def get(self, name: str) -> Effect:
        """Return an effect by its stable name."""
        return self.effects[name]

    def enabled(self, name: str) -> bool:
        """Whether the named effect is switched on."""
        return self.effects[name].enabled

    def enabled_names(self) -> list[str]:
        """Names of the effects that are on, in the stable order."""
        return [name for name in EFFECT_NAMES if self.effects[name].enabled]

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Plain representation for YAML/JSON ground truth."""
        return {name: self.effects[name].to_dict() for name in EFFECT_NAMES}


#: The 3-vectors of an effect (not one value per joint), and what their values are.
_POINT_VALUES = {
    'com_m': "the x, y, z of the centre of mass in the robot's payload frame [m]",
    'inertia_kgm2': 'the principal moments of inertia Ixx, Iyy, Izz about the centre of mass '
    '[kg*m^2]',
}


def _parse_effect(cls: type[Effect], data: dict[str, Any], n: int, where: str) -> Effect:
    names = [item.name for item in fields(cls)]
    check_keys(data, names, where)
    kwargs: dict[str, Any] = {}
    for item in fields(cls):
        if item.name not in data:
            if item.name in cls.vector_fields:
                neutral = 1.0 if item.name in {'scale', 'velocity'} else 0.0
                kwargs[item.name] = float_vector(neutral, f'{where}.{item.name}', n)
            continue
        value = data[item.name]
        if item.name in cls.vector_fields:
            minimum = 0.0 if item.name not in {'offset'} else None
            exclusive = item.name in {'scale', 'velocity'}
            kwargs[item.name] = float_vector(
                value, f'{where}.{item.name}', n, minimum=minimum, exclusive_minimum=exclusive
            )
        elif item.name == 'enabled':
            if not isinstance(value, bool):
                raise ConfigError(f'{where}.enabled: expected true or false, got {value!r}')
            kwargs[item.name] = value
        elif item.name in _POINT_VALUES:
            vector = float_vector(value, f'{where}.{item.name}', 3, each=_POINT_VALUES[item.name])
            kwargs[item.name] = tuple(vector.tolist())
            problem = (
                principal_moments_problem(np.array(kwargs[item.name]))
                if item.name == 'inertia_kgm2'
                else None
            )
            if problem is not None:  # pinocchio refuses a negative one, takes the rest
                raise ConfigError(
                    f'{where}.inertia_kgm2: {value!r}: {problem}; give the principal moments '
                    'about the centre of mass ([0, 0, 0]: a point mass)'
                )
        elif item.name == 'shape':
            if value not in STRIBECK_SHAPES:
                raise ConfigError(
                    f'{where}.shape: expected one of {list(STRIBECK_SHAPES)}, got {value!r}'
                )
            kwargs[item.name] = value
        elif item.name == 'joint':
            if not isinstance(value, str):
                raise ConfigError(f'{where}.joint: expected a joint name, got {value!r}')
            kwargs[item.name] = value
        elif item.name == 'periods_per_motor_turn':
            # sin(p N q) with p = 0 is no ripple: the effect would be listed, yet add nothing.
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ConfigError(
                    f'{where}.{item.name}: expected an integer >= 1 (the ripple periods in one '
                    f'motor turn, e.g. the pole pairs or slots), got {value!r}'
                )
            kwargs[item.name] = value
        else:
            if not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ConfigError(f'{where}.{item.name}: expected a number, got {value!r}')
            kwargs[item.name] = float(value)
    effect = cls(**kwargs)
    for key in (
        'smoothing_velocity',
        'mass_kg',
        'delay_s',
        'arm_base_m',
        'arm_link_m',
        'mass_rel_std',
        'com_std_m',
        'warm_scale',
        'warm_up_s',
    ):
        if hasattr(effect, key) and getattr(effect, key) < 0:
            raise ConfigError(f'{where}.{key}: must be >= 0, got {getattr(effect, key)}')
    _check_mass_rel_std(effect, where)
    delay = getattr(effect, 'delay_s', 0.0)
    if delay > MAX_SIGNAL_DELAY_S:
        raise ConfigError(
            f'{where}.delay_s: must be <= {MAX_SIGNAL_DELAY_S:g} s, got {delay:g}: a drive bus '
            'and current filter lag by milliseconds, and the identification models the delay '
            'to first order, which holds only for lags far below the motion time scale'
        )
    return effect


def _check_mass_rel_std(effect: Effect, where: str) -> None:
    """Refuse a mass error that would draw masses <= 0 more than rarely (``MAX_MASS_REL_STD``)."""
    std = getattr(effect, 'mass_rel_std', 0.0)
    if std > MAX_MASS_REL_STD:
        raise ConfigError(
            f'{where}.mass_rel_std: must be <= {MAX_MASS_REL_STD:g}, got {std:g}: masses are '
            'scaled by 1 + mass_rel_std * N(0, 1), which is <= 0 (a body of negative mass) '
            f'for {100 * non_positive_mass_chance(std):.2g} % of the links at {std:g}, '
            f'{100 * non_positive_mass_chance(MAX_MASS_REL_STD):.2g} % at {MAX_MASS_REL_STD:g}'
        )


def non_positive_mass_chance(mass_rel_std: float) -> float:
    """The chance that 1 + mass_rel_std * z <= 0 for z ~ N(0, 1): P(z <= -1 / mass_rel_std)."""
    return 0.5 * math.erfc(1.0 / (mass_rel_std * math.sqrt(2.0))) if mass_rel_std > 0 else 0.0


def effects_from_dict(data: object, joints: tuple[str, ...], where: str = 'effects') -> EffectSet:
    """Parse the ``effects`` mapping of a twin config; missing effects are disabled.

    Raises:
        ConfigError: an unknown effect name or key, or a bad value (names the key).
    """
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ConfigError(
            f'{where}: expected a mapping of effect name to settings '
            f'(e.g. viscous_friction: {{enabled: true}}), got {type(data).__name__} {data!r}'
        )
    unknown = sorted(str(key) for key in data if key not in EFFECT_NAMES)
    if unknown:
        raise ConfigError(
            f'{where}: unknown effect(s) {unknown}; known effects: {list(EFFECT_NAMES)}'
        )
    effects = {}
    for name, cls in _CLASSES.items():
        section = data.get(name)
        section = {} if section is None else section
        if not isinstance(section, dict):
            raise ConfigError(
                f'{where}.{name}: expected a mapping of setting to value '
                f'(e.g. {{enabled: true}}), got {type(section).__name__} {section!r}'
            )
        effects[name] = _parse_effect(cls, section, len(joints), f'{where}.{name}')
    spring = effects['gravity_spring']
    assert isinstance(spring, GravitySpring)
    if spring.enabled and spring.joint not in joints:
        raise ConfigError(
            f'{where}.gravity_spring.joint: {spring.joint!r} is not one of {list(joints)}'
        )
    return EffectSet(effects)
