"""The identified rigid-body and drive model: what ``physics.identification`` estimates.

    tau_u  = (1 + g) * (RNEA_theta(q, v, a) + N^2 a r) + balancer(q) + friction(v, tau_link)
             + offset - d * rate(tau_link) + cogging(q - d v)
    tau    = RNEA_theta(q, v, a) + balancer(q) + offset      (joint-torque labels: link side)

theta: every body's inertial parameters (pinocchio's 10 per body); r: rotor inertia, motor side
[kg*m^2]; g: the label gain per joint (the torque constant's error: tau_u from currents is off
by 1 / scale, so g = 1 / scale - 1); balancer: a spring or gas balancer's torque on the joints
that carry one (``physics.balancer``: its geometry, ratio and phase, and three force
coefficients); friction per joint from the laws in ``FRICTION_LAWS``, with
tau_link = RNEA_theta + balancer the load the load-dependent friction grows with; offset:
current-sensor (or torque-sensor) offsets [N*m]; d: the labels' delay behind the positions [s],
with rate(tau_link) = dtau_link/dq v + dtau_link/dv a (the part that needs the jerk left out);
cogging: per joint at most one ripple s sin(p N q) + c cos(p N q), p periods per motor turn, N the
gear ratio, evaluated at the labels' time q - d v (``physics.cogging`` finds it on the full band;
with d = 0, the torque the drive needs now, at q).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import pinocchio as pin

from id_learning.errors import CheckpointError
from id_learning.physics.balancer import BALANCER_TERMS, balancer_basis
from id_learning.physics.effects import FRICTION_LAWS, friction_law
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_inertia_joint_side, rotor_inertia_torque

__all__ = [
    'FRICTION_LAWS',
    'IdentifiedPhysics',
    'cogging_basis',
    'friction_columns',
    'sum_parts',
]

#: Step of the central difference along (v, a) that gives the link torque's rate [s].
RATE_STEP_S = 1e-4

#: Friction laws per joint, each linear in its coefficient (``Effect.law_column``): viscous d v;
#: coulomb F_c tanh(v / v_eps); stribeck F_s exp(-(v / v_s)^2) tanh(v / v_eps); load_dependent
#: mu |tau_link| tanh(v / v_eps). Unit of each coefficient: its effect's parameter's.
FRICTION_UNITS = {law: friction_law(law).parameters[0].unit for law in FRICTION_LAWS}


def sum_parts(parts: dict[str, np.ndarray]) -> np.ndarray:
    """The total torque (B, n) [N*m] of a decomposition's parts, all of one shape."""
    values = iter(parts.values())
    total = np.array(next(values), dtype=float)
    for part in values:
        total += part
    return total


def friction_columns(
    laws: tuple[str, ...],
    v: np.ndarray,
    tau_link: np.ndarray,
    smoothing_velocity: float,
    stribeck_velocity: np.ndarray,
) -> dict[str, np.ndarray]:
    """Each law's column per joint, (..., n) each: friction = sum over laws of c_law * column.

    Args:
        laws: the laws wanted (names from FRICTION_LAWS).
        v: (..., n) joint velocities [rad/s].
        tau_link: (..., n) link-side joint torque [N*m] (load-dependent friction only).
        smoothing_velocity: v_eps [rad/s], where the sign turns smoothly through zero.
        stribeck_velocity: (n,) v_s per joint [rad/s].
    """
    return {
        law: friction_law(law).law_column(v, tau_link, smoothing_velocity, stribeck_velocity)
        for law in laws
    }


def cogging_basis(q: np.ndarray, gear_ratio: float, period: int) -> np.ndarray:
    """The sine and cosine of p N q (..., 2): a cogging ripple's columns at one joint's positions.

    Args:
        q: (...,) the joint's positions [rad].
        gear_ratio: N, motor turns per joint turn.
        period: p, ripple periods per motor turn.
    """
    phase = period * gear_ratio * np.asarray(q, dtype=float)
    return np.stack([np.sin(phase), np.cos(phase)], axis=-1)


@dataclass(frozen=True, eq=False)
class IdentifiedPhysics:
    """An identified rigid-body and drive model (see the module docstring).

    Attributes:
        robot: the robot (URDF kinematics, drives).
        target: 'motor' or 'joint'.
        theta: (10 B,) inertial parameters of every body.
        rotor: (n,) rotor inertia, motor side [kg*m^2] (zero for joint torques).
        gain: (n,) label gain g (zero for joint torques).
        friction: law -> (n,) coefficients.
        stribeck_velocity: (n,) v_s per joint [rad/s].
        smoothing_velocity: v_eps [rad/s].
        offset: (n,) torque offsets [N*m].
        delay_s: the labels' delay behind the positions [s].
        balancer: (n, 3) force coefficients of each joint's balancer [N*m] (zero rows: none).
        balancer_ratio: (n,) each balancer's ratio r of its arms.
        balancer_phase: (n,) each balancer's phase [rad].
        cogging: (n, 2) each joint's cogging ripple, sine and cosine coefficients of p N q [N*m]
            (empty: none; filled with zeros).
        cogging_periods: (n,) its periods p per motor turn (0: none; empty: none).
        report: JSON-ready account of the identification (base parameters, intervals, ...).
    """

    robot: RobotConfig
    target: str
    theta: np.ndarray
    rotor: np.ndarray
    gain: np.ndarray
    friction: dict[str, np.ndarray]
    stribeck_velocity: np.ndarray
    smoothing_velocity: float
    offset: np.ndarray
    delay_s: float
    balancer: np.ndarray
    balancer_ratio: np.ndarray
    balancer_phase: np.ndarray
    cogging: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cogging_periods: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    report: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Give a model without cogging its zero rows (n, 2) and periods (n,)."""
        n = self.robot.n_joints
        if np.size(self.cogging_periods) == 0:
            object.__setattr__(self, 'cogging', np.zeros((n, 2)))
            object.__setattr__(self, 'cogging_periods', np.zeros(n, dtype=int))
        object.__setattr__(self, 'cogging_periods', np.asarray(self.cogging_periods, dtype=int))

    @cached_property
    def dynamics(self) -> RigidBodyDynamics:
        """The rigid body with the identified inertial parameters."""
        return RigidBodyDynamics.from_config(self.robot).with_inertial_parameters(self.theta)

    @property
    def laws(self) -> tuple[str, ...]:
        """The friction laws in the model, in FRICTION_LAWS order."""
        return tuple(law for law in FRICTION_LAWS if law in self.friction)

    def balancer_torque(self, q: np.ndarray) -> np.ndarray:
        """The balancers' torque (..., n) [N*m] at positions q (..., n) [rad]."""
        q = np.asarray(q, dtype=float)
        torque = np.zeros_like(q)
        for j in np.flatnonzero(np.any(self.balancer != 0, axis=1)):
            basis = balancer_basis(q[..., j], self.balancer_ratio[j], self.balancer_phase[j])
            torque[..., j] = basis @ self.balancer[j]
        return torque

    def cogging_torque(self, q: np.ndarray) -> np.ndarray:
        """The cogging ripples' torque (..., n) [N*m] at positions q (..., n) [rad]."""
        q = np.asarray(q, dtype=float)
        torque = np.zeros_like(q)
        gear = self.robot.drives.gear_ratio
        for j in np.flatnonzero(self.cogging_periods):
            basis = cogging_basis(q[..., j], gear[j], int(self.cogging_periods[j]))
            torque[..., j] = basis @ self.cogging[j]
        return torque

    def link_rate(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """dtau_link/dq v + dtau_link/dv a (B, n) [N*m/s]: the link torque's rate, jerk left out.

        A central difference along (v, a), as the identification computes it.
        """
        h = RATE_STEP_S
        ahead = self.dynamics.rnea(q + h * v, v + h * a, a) + self.balancer_torque(q + h * v)
        behind = self.dynamics.rnea(q - h * v, v - h * a, a) + self.balancer_torque(q - h * v)
        rate: np.ndarray = (ahead - behind) / (2 * h)
        return rate

    def parts(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> dict[str, np.ndarray]:
        """The torque's parts, each (B, n) [N*m]; they sum to ``torque``.

        'rigid_body' and 'rotor_inertia' include the label gain; 'balancer' acts on the links,
        'friction' and 'offset' are the drive's, 'delay' the labels' lag.
        """
        q, v, a = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, v, a))
        rigid = self.dynamics.rnea(q, v, a)
        balancer = self.balancer_torque(q)
        delay = -self.delay_s * self.link_rate(q, v, a) if self.delay_s else np.zeros_like(q)
        scale = 1.0 + self.gain
        gear = self.robot.drives.gear_ratio
        columns = friction_columns(
            self.laws, v, rigid + balancer, self.smoothing_velocity, self.stribeck_velocity
        )
        friction = np.zeros_like(v)
        for law, column in columns.items():
            friction += self.friction[law] * column
        return {
            'rigid_body': scale * rigid,
            'rotor_inertia': rotor_inertia_torque(a, scale * self.rotor, gear),
            'balancer': balancer,
            'friction': friction,
            'offset': np.broadcast_to(self.offset, v.shape).copy(),
            'delay': delay,
            'cogging': self.cogging_torque(q - self.delay_s * v),
        }

    def torque(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        return sum_parts(self.parts(q, v, a))

    def sample_function(self) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """``torque`` of one sample, q, v, a (n,) -> (n,) [N*m], folded for the online path."""
        dynamics = self.dynamics
        model, data = dynamics.model, dynamics.model.createData()
        index = dynamics.joint_index
        if not np.array_equal(index, np.arange(len(index))):
            return lambda q, v, a: self.torque(q[None], v[None], a[None])[0]
        scale = 1.0 + self.gain
        rotor = rotor_inertia_joint_side(scale * self.rotor, self.robot.drives.gear_ratio)
        coefficients = [self.friction[law] for law in self.laws]
        laws, eps, vs = self.laws, self.smoothing_velocity, self.stribeck_velocity
        offset, rnea = self.offset, pin.rnea

        balancer, delay, h = self.balancer_torque, self.delay_s, RATE_STEP_S
        rippled = np.flatnonzero(self.cogging_periods)
        ripple = self.cogging_periods[rippled] * self.robot.drives.gear_ratio[rippled]
        ripple_sin, ripple_cos = self.cogging[rippled, 0], self.cogging[rippled, 1]
        sin, cos = np.sin, np.cos

        def torque_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            rigid = rnea(model, data, q, v, a).copy()
            spring = balancer(q)
            tau_link = rigid + spring
            tau: np.ndarray = scale * rigid + spring + rotor * a + offset
            if delay:
                ahead = rnea(model, data, q + h * v, v + h * a, a) + balancer(q + h * v)
                behind = rnea(model, data, q - h * v, v - h * a, a) + balancer(q - h * v)
                tau -= delay * (ahead - behind) / (2 * h)
            for c, column in zip(
                coefficients, friction_columns(laws, v, tau_link, eps, vs).values(), strict=True
            ):
                tau += c * column
            if len(rippled):
                phase = ripple * (q[rippled] - delay * v[rippled])
                tau[rippled] += ripple_sin * sin(phase) + ripple_cos * cos(phase)
            return tau

        return torque_one

    # -- storage ----------------------------------------------------------------------------------
    def arrays(self) -> dict[str, np.ndarray]:
        """The identified values as named arrays (for safetensors)."""
        out = {
            'theta': self.theta,
            'rotor': self.rotor,
            'gain': self.gain,
            'offset': self.offset,
            'stribeck_velocity': self.stribeck_velocity,
            'balancer': self.balancer,
            'balancer_ratio': self.balancer_ratio,
            'balancer_phase': self.balancer_phase,
            'cogging': self.cogging,
            'cogging_periods': self.cogging_periods,
        }
        out.update({f'friction.{law}': values for law, values in self.friction.items()})
        return {name: np.ascontiguousarray(value, dtype=float) for name, value in out.items()}

    def metadata(self) -> dict[str, Any]:
        """JSON-ready settings and the report (``from_arrays`` rebuilds the model)."""
        return {
            'target': self.target,
            'friction_laws': list(self.laws),
            'smoothing_velocity': self.smoothing_velocity,
            'delay_s': self.delay_s,
            'report': self.report,
        }

    @classmethod
    def from_arrays(
        cls, robot: RobotConfig, arrays: dict[str, np.ndarray], metadata: dict[str, Any]
    ) -> IdentifiedPhysics:
        """Rebuild from ``arrays`` and ``metadata`` output.

        Arrays saved before the cogging was identified lack 'cogging' and 'cogging_periods':
        the model then has none.

        Raises:
            CheckpointError: an array is missing or has the wrong shape, or a cogging period is
                no whole number >= 0.
        """
        n = robot.n_joints
        laws = tuple(metadata.get('friction_laws', ()))
        vectors = ('rotor', 'gain', 'offset', 'stribeck_velocity', 'balancer_ratio')
        expected = {
            'theta': (10 * n,),
            **dict.fromkeys((*vectors, 'balancer_phase'), (n,)),
            **{f'friction.{law}': (n,) for law in laws},
            'balancer': (n, BALANCER_TERMS),
        }
        cogging = {'cogging': (n, 2), 'cogging_periods': (n,)}
        if cogging.keys() & arrays.keys():  # an artifact saved before the stage holds neither
            expected |= cogging
        found = {name: np.shape(value) for name, value in arrays.items()}
        if found != expected or not set(laws) <= set(FRICTION_LAWS):
            raise CheckpointError(
                f'identified physics: expected arrays {expected} for laws {list(laws)}, got '
                f'{found}'
            )
        periods = np.asarray(arrays.get('cogging_periods', np.zeros(n)), dtype=float)
        if not np.all((periods >= 0) & (periods == np.round(periods))):
            raise CheckpointError(
                f'identified physics: cogging periods per motor turn must be whole numbers >= 0, '
                f'got {periods.tolist()}'
            )
        return cls(
            robot=robot,
            target=str(metadata['target']),
            theta=np.asarray(arrays['theta'], dtype=float),
            rotor=np.asarray(arrays['rotor'], dtype=float),
            gain=np.asarray(arrays['gain'], dtype=float),
            friction={law: np.asarray(arrays[f'friction.{law}'], dtype=float) for law in laws},
            stribeck_velocity=np.asarray(arrays['stribeck_velocity'], dtype=float),
            smoothing_velocity=float(metadata['smoothing_velocity']),
            offset=np.asarray(arrays['offset'], dtype=float),
            delay_s=float(metadata.get('delay_s', 0.0)),
            balancer=np.asarray(arrays['balancer'], dtype=float),
            balancer_ratio=np.asarray(arrays['balancer_ratio'], dtype=float),
            balancer_phase=np.asarray(arrays['balancer_phase'], dtype=float),
            cogging=np.asarray(arrays.get('cogging', np.zeros((n, 2))), dtype=float),
            cogging_periods=periods.astype(int),
            report=dict(metadata.get('report') or {}),
        )
