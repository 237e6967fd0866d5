"""The twin as a plant: the motion that a commanded motor torque produces on the hidden robot.

The twin's recordings run its inverse dynamics along a planned motion; a closed loop needs the
other direction. ``TwinPlant`` holds the same hidden robot as ``simulate`` for a config (true
link parameters and payload, rotor inertia, balancer, friction, cogging, torque-constant scale,
encoder offset) and integrates

    (M(q) + J_rotor N^2) a = k_t,scale * (tau_cmd - o) - (C(q, v) v + g(q) - spring(q) + f(q, v)),

where tau_cmd is a torque in the drive's datasheet units (tau_u), as a controller commands it,
and o the current sensor's offset in the same units (``torque_offset``): the drive's current loop
regulates the current its sensor measures, the one the labels are made of, so it delivers the
command less the offset, and the command a motion needs (``command``) holds the offset as the
labels do. Friction is stiff around zero velocity (a smoothed sign), so each step treats it
implicitly in the velocity (linearised backward Euler): explicit Euler would need microsecond
steps. The currents' delay is the labels' alone and acts on no motion. A
friction that warms up over the shift (``warm_scale``, ``warm_up_s``) follows the plant's time
from the config's ``shift_start_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from id_learning.robot.drives import rotor_inertia_joint_side
from id_learning.twin.effects import (
    GravitySpring,
    JointOffset,
    RotorInertia,
    TorqueConstantScale,
    TorqueOffset,
)
from id_learning.twin.simulate import (
    TwinConfig,
    friction_and_cogging,
    random_streams,
    true_dynamics,
)

__all__ = ['PlantState', 'TwinPlant']

_DERIVATIVE_STEP = 1e-6  # rad/s, for the friction's velocity derivative


@dataclass
class PlantState:
    """The true motion of the plant.

    Positions [rad], velocities [rad/s], link torque [N*m] and the time since the plant started
    [s] (friction warms up over the shift).
    """

    q: np.ndarray
    v: np.ndarray
    link_torque: np.ndarray
    time_s: float = 0.0


class TwinPlant:
    """The hidden robot of a twin config, driven by commanded motor torques.

    Args:
        config: the twin config (the robot is drawn from its ``robot_seed`` as ``simulate``
            draws it, so a plant and the recordings of one config share one robot).
    """

    def __init__(self, config: TwinConfig) -> None:
        """Draw the hidden robot; nothing is integrated yet."""
        robot, effects = config.robot, config.effects
        self.config = config
        self.robot = robot
        self.dynamics = true_dynamics(config, random_streams(config.true_robot_seed)[1])
        self._mass_and_bias = self.dynamics.sample_mass_and_bias()
        self.gear = robot.drives.gear_ratio
        rotor = effects.get('rotor_inertia')
        assert isinstance(rotor, RotorInertia)
        scale = rotor.scale if rotor.enabled else 1.0
        self.rotor_inertia_joint_side = rotor_inertia_joint_side(
            robot.drives.rotor_inertia * scale, self.gear
        )
        kt = effects.get('torque_constant_scale')
        assert isinstance(kt, TorqueConstantScale)
        self.kt_scale = kt.scale if kt.enabled else np.ones(robot.n_joints)
        spring = effects.get('gravity_spring')
        assert isinstance(spring, GravitySpring)
        self._spring = spring if spring.enabled else None
        self._spring_joint = robot.joints.index(spring.joint) if spring.enabled else -1
        offset = effects.get('joint_offset')
        assert isinstance(offset, JointOffset)
        self.encoder_offset = (
            np.asarray(offset.offset, dtype=float) if offset.enabled else np.zeros(robot.n_joints)
        )
        sensor = effects.get('torque_offset')
        assert isinstance(sensor, TorqueOffset)
        #: (n,) the current sensor's offset in tau_u units [N*m]: the loop delivers less by it.
        self.sensor_offset = (
            np.asarray(sensor.offset, dtype=float) if sensor.enabled else np.zeros(robot.n_joints)
        )

    # -- torques --------------------------------------------------------------------------------
    def _spring_torque(self, q: np.ndarray) -> np.ndarray:
        out = np.zeros_like(q)
        if self._spring is not None:
            j = self._spring_joint
            out[..., j] = self._spring.torque_on_joint(q[..., j])
        return out

    def _friction(
        self, q: np.ndarray, v: np.ndarray, link: np.ndarray, time_s: float
    ) -> np.ndarray:
        """(n,) friction and cogging torque [N*m] of one state (the link torque loads friction)."""
        shift = np.array([self.config.shift_start_s + time_s])
        parts = friction_and_cogging(
            self.config.effects, v[None], q[None], link[None], self.gear, shift_time_s=shift
        )
        return np.sum(list(parts.values()), axis=0)[0] if parts else np.zeros_like(q)

    def motor_torque(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, time_s: np.ndarray | None = None
    ) -> np.ndarray:
        """(N, n) joint-side motor torque [N*m] the true motion (N, n) needs (inverse dynamics).

        What ``simulate`` puts in tau_u_clean times the torque-constant scale, less the label's
        offset, on the undelayed motion: the twin's true inverse dynamics. ``time_s`` (N,): the
        samples' times since the recording started (default: one IPO period apart from 0).
        """
        q, v, a = (np.atleast_2d(x) for x in (q, v, a))
        if time_s is None:
            time_s = np.arange(len(q)) * self.robot.ipo_period_s
        shift = self.config.shift_start_s + np.asarray(time_s, dtype=float)
        link = self.dynamics.rnea(q, v, a) - self._spring_torque(q)
        parts = friction_and_cogging(
            self.config.effects, v, q, link, self.gear, shift_time_s=shift
        )
        friction = np.sum(list(parts.values()), axis=0) if parts else 0.0
        out: np.ndarray = link + self.rotor_inertia_joint_side * a + friction
        return out

    def command(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, time_s: np.ndarray | None = None
    ) -> np.ndarray:
        """(N, n) the command in tau_u units under which the drive delivers ``motor_torque``.

        The true inverse dynamics as a feed-forward: the motor torque over the torque-constant
        scale (tau_u uses the datasheet k_t) plus the current sensor's offset, which the current
        loop regulates on; what ``simulate``'s noise-free label holds for the undelayed motion.
        """
        tau_u: np.ndarray = self.motor_torque(q, v, a, time_s) / self.kt_scale + self.sensor_offset
        return tau_u

    # -- integration ----------------------------------------------------------------------------
    def start(self, q: np.ndarray, v: np.ndarray, a: np.ndarray | None = None) -> PlantState:
        """A state of positions and velocities (n,).

        Its link torque, which loads friction, is that of acceleration ``a`` (zero if None).
        """
        q, v = np.asarray(q, dtype=float).copy(), np.asarray(v, dtype=float).copy()
        mass, bias = self._mass_and_bias(q, v)
        accel = np.zeros_like(q) if a is None else np.asarray(a, dtype=float)
        return PlantState(q, v, mass @ accel + bias - self._spring_torque(q))

    def step(self, state: PlantState, tau_command: np.ndarray, dt: float) -> PlantState:
        """Advance by ``dt`` [s] under a commanded torque (n,) in tau_u units (datasheet k_t).

        The drive delivers k_t,scale times the command less the current sensor's offset.

        Linearised backward Euler in the velocity for friction, then the position with the new
        velocity (semi-implicit Euler).
        """
        q, v = state.q, state.v
        mass, bias = self._mass_and_bias(q, v)
        mass = mass + np.diag(self.rotor_inertia_joint_side)
        spring = self._spring_torque(q)
        friction = self._friction(q, v, state.link_torque, state.time_s)
        slope = (
            self._friction(q, v + _DERIVATIVE_STEP, state.link_torque, state.time_s) - friction
        ) / _DERIVATIVE_STEP
        delivered = self.kt_scale * (tau_command - self.sensor_offset)
        force = delivered - (bias - spring + friction)
        dv = np.linalg.solve(mass + dt * np.diag(np.maximum(slope, 0.0)), dt * force)
        v_next = v + dv
        link = mass @ (dv / dt) - np.diag(self.rotor_inertia_joint_side) @ (dv / dt)
        return PlantState(q + dt * v_next, v_next, link + bias - spring, state.time_s + dt)
