"""The library of candidate effects: named groups of regressor columns.

Each candidate is one of the twin's stable effect names on one joint (or robot-wide), and a group
of columns X (N, n, k) built from q, v, a and the nominal model's own quantities, such that the
effect adds X @ theta [N*m] to the motor torque tau_u of every joint. theta is in physical units
(see ``PARAMETERS``). Each candidate also carries the condition under which the excitation can
show it at all (``testability``) and a sign/size rule for a physical value (``plausibility``).

The nominal model is the URDF's rigid-body dynamics plus the datasheet rotor inertia:

    tau_nominal = RNEA(q, v, a) + J_m N^2 a        (motor target; RNEA only for joint torques)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin
from scipy import stats

from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.errors import ConfigError, RobotModelError
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_inertia_torque
from id_learning.robot.dynamics import N_INERTIAL_PARAMETERS, RigidBodyDynamics

__all__ = [
    'JOINT_COLUMNS',
    'PARAMETERS',
    'SPECIAL_CASES',
    'CandidateSpec',
    'NominalModel',
    'NominalQuantities',
    'build_library',
    'candidate_columns',
    'describe_parameters',
    'payload_parameter_map',
    'plausibility',
    'testability',
    'transform_dynamic_parameters',
]

#: Parameters of each effect's columns, in column order, with units (k of them, or a prefix).
PARAMETERS: dict[str, tuple[tuple[str, str], ...]] = {
    'viscous_friction': (('coefficient', 'N*m*s/rad'),),
    'coulomb_friction': (('level', 'N*m'),),
    'stribeck_friction': (('level', 'N*m'),),
    'load_dependent_friction': (('coefficient', '1'),),
    'rotor_inertia': (('rotor_inertia_change_motor_side', 'kg*m^2'),),
    'gravity_spring': (('c1', 'N*m/rad'), ('c2', 'N*m/rad^2'), ('c3', 'N*m/rad^3')),
    'payload_mass': (('mass', 'kg'), ('first_moment_x', 'kg*m'), ('first_moment_y', 'kg*m'),
                     ('first_moment_z', 'kg*m')),
    'joint_offset': (('offset', 'rad'),),
    'torque_constant_scale': (('label_gain_change', '1'),),
    'signal_delay': (('delay', 's'),),
    'cogging': (('sine', 'N*m'), ('cosine', 'N*m')),
    'torque_offset': (('offset', 'N*m'),),
    'inertial_parameter_error': (('base_parameter', 'SI'),),
}  # fmt: skip

ROBOT_WIDE = ('payload_mass', 'signal_delay', 'inertial_parameter_error')

#: Effects that are special cases of a more general one: the same physics with fewer columns. A
#: payload is a mass at the flange and a rotor inertia the inertia of a moving part, both errors
#: of the mass distribution that ``inertial_parameter_error`` (every link's base parameters) can
#: also take. The general effect is then no alternative explanation but the same one with more
#: freedom: where the special case explains what the data show, it is named and the general
#: effect is not listed as its alias (parsimony; a kinematic joint offset or a balancer spring,
#: which the link parameters can only mimic, stay aliases).
SPECIAL_CASES = {
    'payload_mass': 'inertial_parameter_error',
    'rotor_inertia': 'inertial_parameter_error',
}


@dataclass(frozen=True, eq=False)
class CandidateSpec:
    """One candidate: an effect name, the joint it sits on, and the settings of its columns.

    Attributes:
        name: the twin's stable effect name.
        joint: index of the joint the effect sits on; None for robot-wide effects.
        joint_name: that joint's name ('' for robot-wide effects).
        settings: JSON-ready values the columns depend on (v_s, cogging periods, basis, ...).
    """

    name: str
    joint: int | None = None
    joint_name: str = ''
    settings: Mapping[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """Unique, readable key: name[joint, setting]."""
        parts = [self.joint_name] if self.joint_name else []
        if self.name == 'stribeck_friction':
            parts.append(f'v_s={self.settings["velocity"]:g}')
        if self.name == 'cogging':
            parts.append(f'p={self.settings["periods_per_motor_turn"]}')
        if self.name == 'payload_mass':
            parts.append(str(self.settings['frame']))
        return f'{self.name}[{", ".join(parts)}]' if parts else self.name

    def replace_settings(self, **changes: Any) -> CandidateSpec:
        """A copy with some settings changed (a refined Stribeck velocity, payload COM)."""
        return CandidateSpec(self.name, self.joint, self.joint_name, {**self.settings, **changes})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; ``from_dict`` rebuilds it."""
        return {
            'name': self.name,
            'joint': self.joint_name or None,
            'settings': dict(self.settings),
            'label': self.label,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], joints: tuple[str, ...]) -> CandidateSpec:
        """Rebuild from ``to_dict`` output for a robot with these joints."""
        joint_name = data.get('joint') or ''
        if joint_name and joint_name not in joints:
            raise RobotModelError(
                f'effect {data.get("label", data["name"])} sits on joint {joint_name!r}, which '
                f'the robot {list(joints)} does not have'
            )
        joint = joints.index(joint_name) if joint_name else None
        return cls(str(data['name']), joint, joint_name, dict(data.get('settings') or {}))


@dataclass(frozen=True, eq=False)
class NominalQuantities:
    """The nominal model's quantities along a motion; arrays (N, n) unless stated.

    Attributes:
        q, v, a, jerk: motion [rad, rad/s, rad/s^2, rad/s^3].
        tau_rigid: RNEA(q, v, a) of the URDF [N*m].
        tau_rotor: J_m N^2 a with the datasheet rotor inertia [N*m] (zero for joint torques).
        tau_nominal: tau_rigid + tau_rotor [N*m].
        dtau_dq: (N, n, n) d tau_rigid_i / d q_j [N*m/rad], or None if not computed.
        dtau_dv: (N, n, n) d tau_rigid_i / d v_j [N*m*s/rad], or None.
        mass: (N, n, n) joint-space mass matrix [kg*m^2], or None.
        regressor: (N, n, 10 * bodies) inertial-parameter regressor, or None.
    """

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    jerk: np.ndarray
    tau_rigid: np.ndarray
    tau_rotor: np.ndarray
    tau_nominal: np.ndarray
    dtau_dq: np.ndarray | None = None
    dtau_dv: np.ndarray | None = None
    mass: np.ndarray | None = None
    regressor: np.ndarray | None = None


class NominalModel:
    """URDF rigid-body dynamics plus datasheet rotor inertia, with the derivatives candidates use.

    Args:
        robot: the robot config (URDF, joints, drives).
        target: 'motor' (tau_u from currents: rotor inertia included) or 'joint' (joint torque).
    """

    def __init__(self, robot: RobotConfig, target: str = 'motor') -> None:
        """Build the URDF model (reads the URDF)."""
        self.robot = robot
        self.target = target
        self.dynamics = RigidBodyDynamics.from_config(robot)
        model = self.dynamics.model
        self._index = np.array(
            [model.joints[model.getJointId(name)].idx_v for name in robot.joints]
        )
        self._data = model.createData()
        self._payload_maps: dict[tuple[str, tuple[float, ...]], tuple[int, np.ndarray]] = {}

    def payload_map(self, frame: str, com_guess_m: Sequence[float]) -> tuple[int, np.ndarray]:
        """``payload_parameter_map`` of this model, computed once per frame and COM guess."""
        key = (frame, tuple(float(x) for x in com_guess_m))
        if key not in self._payload_maps:
            self._payload_maps[key] = payload_parameter_map(self, frame, np.asarray(key[1]))
        return self._payload_maps[key]

    @property
    def rotor_inertia_joint_side(self) -> np.ndarray:
        """(n,) J_m N^2 [kg*m^2]; zero when the target is the joint torque."""
        drives = self.robot.drives
        if self.target != 'motor':
            return np.zeros(self.robot.n_joints)
        return drives.rotor_inertia * drives.gear_ratio**2

    def evaluate(
        self,
        q: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        jerk: np.ndarray | None = None,
        *,
        derivatives: bool = False,
        regressor: bool = False,
    ) -> NominalQuantities:
        """Evaluate the nominal model along a motion.

        Args:
            q: (N, n) joint positions [rad].
            v: (N, n) joint velocities [rad/s].
            a: (N, n) joint accelerations [rad/s^2].
            jerk: (N, n) joint jerks [rad/s^3]; zero if None.
            derivatives: also compute d tau / d q, d tau / d v and M(q).
            regressor: also compute the inertial-parameter regressor.
        """
        q, v, a = (np.asarray(x, dtype=float) for x in (q, v, a))
        jerk = np.zeros_like(a) if jerk is None else np.asarray(jerk, dtype=float)
        tau_rigid = self.dynamics.rnea(q, v, a)
        if self.target == 'motor':
            drives = self.robot.drives
            tau_rotor = rotor_inertia_torque(a, drives.rotor_inertia, drives.gear_ratio)
        else:
            tau_rotor = np.zeros_like(a)
        dq = dv = mass = None
        if derivatives:
            dq, dv, mass = self._derivatives(q, v, a)
        return NominalQuantities(
            q=q,
            v=v,
            a=a,
            jerk=jerk,
            tau_rigid=tau_rigid,
            tau_rotor=tau_rotor,
            tau_nominal=tau_rigid + tau_rotor,
            dtau_dq=dq,
            dtau_dv=dv,
            mass=mass,
            regressor=self.dynamics.regressor(q, v, a) if regressor else None,
        )

    def _derivatives(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        model, data, ix = self.dynamics.model, self._data, self._index
        n_samples, nv = len(q), model.nv
        dq, dv, mass = (np.empty((n_samples, nv, nv)) for _ in range(3))
        qk, vk, ak = (np.empty(nv) for _ in range(3))
        for k in range(n_samples):
            qk[ix], vk[ix], ak[ix] = q[k], v[k], a[k]
            pin.computeRNEADerivatives(model, data, qk, vk, ak)
            dq[k] = data.dtau_dq
            dv[k] = data.dtau_dv
            mass[k] = data.M  # upper triangle only, in pinocchio's order
        mass = np.triu(mass) + np.swapaxes(np.triu(mass, 1), 1, 2)
        grid = (slice(None), ix[:, None], ix[None, :])
        return dq[grid], dv[grid], mass[grid]

    def nominal_rate(self, quantities: NominalQuantities) -> np.ndarray:
        """D tau_nominal / dt (N, n) [N*m/s] = dtau/dq v + dtau/dv a + (M + J_m N^2) jerk."""
        if quantities.dtau_dq is None or quantities.dtau_dv is None or quantities.mass is None:
            raise ValueError('the nominal rate needs quantities evaluated with derivatives=True')
        inertia = quantities.mass + np.diag(self.rotor_inertia_joint_side)
        return (
            np.einsum('bij,bj->bi', quantities.dtau_dq, quantities.v)
            + np.einsum('bij,bj->bi', quantities.dtau_dv, quantities.a)
            + np.einsum('bij,bj->bi', inertia, quantities.jerk)
        )


# -- rigid-body parameter algebra -----------------------------------------------------------------
def _skew_product(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """S(x)^T S(y) = (x . y) I - y x^T, the building block of inertia tensors."""
    return float(np.dot(x, y)) * np.eye(3) - np.outer(y, x)


def _inertia_to_vector(inertia: np.ndarray) -> np.ndarray:
    """Pinocchio's order of the six inertia entries: xx, xy, yy, xz, yz, zz."""
    return np.array(
        [
            inertia[0, 0],
            inertia[0, 1],
            inertia[1, 1],
            inertia[0, 2],
            inertia[1, 2],
            inertia[2, 2],
        ]
    )


def _vector_to_inertia(values: np.ndarray) -> np.ndarray:
    xx, xy, yy, xz, yz, zz = values
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def transform_dynamic_parameters(
    parameters: np.ndarray, rotation: np.ndarray, translation: np.ndarray
) -> np.ndarray:
    """Express a frame F's dynamic parameters in a frame J; F sits at (rotation, translation) in J.

    With m, first moment h = m c and inertia I_F about F's origin (pinocchio's 10-vector):
    h_J = R h + m p and I_J = R I_F R^T + S(p)^T S(R h) + S(R h)^T S(p) + m S(p)^T S(p). The map
    is linear in the 10-vector, so it also maps regressor columns.
    """
    m = parameters[0]
    h = rotation @ parameters[1:4]
    p = np.asarray(translation, dtype=float)
    inertia = rotation @ _vector_to_inertia(parameters[4:]) @ rotation.T
    inertia = inertia + _skew_product(p, h) + _skew_product(h, p) + m * _skew_product(p, p)
    return np.concatenate([[m], h + m * p, _inertia_to_vector(inertia)])


def payload_parameter_map(
    model: NominalModel, frame: str, com_guess_m: np.ndarray
) -> tuple[int, np.ndarray]:
    """Map a point-mass payload's (m, h = m c) in ``frame`` to its parent body's 10 parameters.

    A point mass has inertia S(h)^T S(h) / m about the frame origin: quadratic in h. Linearised at
    the COM guess c0 (exact when h = m c0) it is -m S(c0)^T S(c0) + S(h)^T S(c0) + S(c0)^T S(h);
    refitting with c0 = h / m converges to the point mass.

    Returns:
        (body index into the regressor's bodies, (10, 4) map from (m, h_x, h_y, h_z)).
    """
    pin_model = model.dynamics.model
    frame_id = pin_model.getFrameId(frame)
    if frame_id >= len(pin_model.frames):
        raise RobotModelError(f'payload frame {frame!r} does not exist in the URDF')
    placement = pin_model.frames[frame_id].placement
    parent = int(pin_model.frames[frame_id].parentJoint)
    c0 = np.asarray(com_guess_m, dtype=float)
    columns = []
    for unit in np.eye(4):
        m, h = unit[0], unit[1:]
        inertia = -m * _skew_product(c0, c0) + _skew_product(h, c0) + _skew_product(c0, h)
        in_frame = np.concatenate([[m], h, _inertia_to_vector(inertia)])
        columns.append(
            transform_dynamic_parameters(in_frame, placement.rotation, placement.translation)
        )
    return parent - 1, np.array(columns).T


# -- the library ----------------------------------------------------------------------------------
def inertial_base_directions(
    model: NominalModel, n_states: int = 400
) -> tuple[np.ndarray, np.ndarray]:
    """Directions of the inertial parameters that the joint torques can and cannot show.

    The regressor on random states inside the joint limits has rank r < 10 B (parameters of
    joints near the base, and combinations along a chain, do not act separately); its right
    singular vectors with non-zero singular values, after scaling each column to unit norm, span
    the identifiable (base) parameters, the others never change any torque. The seed is fixed:
    the basis belongs to the robot.

    Returns:
        (base (10 B, r), null (10 B, 10 B - r)) in physical parameter units.
    """
    limits = model.robot.limits
    rng = np.random.default_rng(20260101)
    n = model.robot.n_joints
    q = rng.uniform(limits.position_lower, limits.position_upper, size=(n_states, n))
    v = rng.uniform(-1.0, 1.0, size=(n_states, n)) * limits.velocity
    a = rng.uniform(-1.0, 1.0, size=(n_states, n)) * limits.acceleration
    y = model.dynamics.regressor(q, v, a).reshape(n_states * n, -1)
    norms = np.linalg.norm(y, axis=0)
    scale = np.where(norms > 1e-12 * max(norms.max(), 1e-300), norms, np.inf)
    scaled = y / scale
    # Eigenvectors of the (small) Gram matrix are the right singular vectors; a direction whose
    # singular value is below 1e-5 of the largest is not identifiable in any practical sense.
    values, vectors = np.linalg.eigh(scaled.T @ scaled)
    order = np.argsort(values)[::-1]
    values, vectors = values[order], vectors[:, order]
    rank = int(np.sum(values > 1e-10 * values[0]))
    silent = np.flatnonzero(~np.isfinite(scale))  # columns that never act at all
    spanning = np.hstack([vectors[:, rank:] / scale[:, None], np.eye(len(scale))[:, silent]])
    u, s, _ = np.linalg.svd(spanning, full_matrices=False)
    null = u[:, s > 1e-9 * s.max()] if s.size and s.max() > 0 else u[:, :0]
    return vectors[:, :rank] / scale[:, None], null


def spring_joints(
    model: NominalModel, quantities: NominalQuantities, config: DiagnosisConfig
) -> list[int]:
    """Joints that may carry a gravity spring (config, or where gravity sweeps a real torque)."""
    joints = model.robot.joints
    if config.gravity_spring_joints is not None:
        unknown = sorted(set(config.gravity_spring_joints) - set(joints))
        if unknown:
            raise ConfigError(
                f'diagnosis.gravity_spring_joints: {unknown} are not joints of {list(joints)}'
            )
        return [joints.index(name) for name in config.gravity_spring_joints]
    step = max(1, len(quantities.q) // 2000)
    gravity = model.dynamics.gravity(quantities.q[::step])
    sweep = gravity.max(axis=0) - gravity.min(axis=0)
    share = sweep / model.robot.limits.torque
    return [j for j in range(len(joints)) if share[j] >= config.gravity_spring_min_share]


def build_library(
    model: NominalModel, quantities: NominalQuantities, config: DiagnosisConfig
) -> list[CandidateSpec]:
    """Every candidate of the enabled effects for this robot, in the effects' stable order."""
    robot = model.robot
    joints = robot.joints
    eps = config.smoothing_velocity
    specs: list[CandidateSpec] = []
    springs = spring_joints(model, quantities, config)
    for name in config.effects:
        if name == 'signal_delay':
            specs.append(CandidateSpec(name))
        elif name == 'inertial_parameter_error':
            base, null = inertial_base_directions(model)
            specs.append(
                CandidateSpec(
                    name,
                    settings={'base_directions': base.tolist(), 'null_directions': null.tolist()},
                )
            )
        elif name == 'payload_mass':
            specs.append(
                CandidateSpec(
                    name, settings={'frame': robot.payload_frame, 'com_guess_m': [0.0, 0.0, 0.0]}
                )
            )
        else:
            for j, joint in enumerate(joints):
                if name == 'stribeck_friction':
                    specs += [
                        CandidateSpec(name, j, joint, {'velocity': vs, 'smoothing_velocity': eps})
                        for vs in config.stribeck_velocities
                    ]
                elif name == 'cogging':
                    specs += [
                        CandidateSpec(name, j, joint, {'periods_per_motor_turn': p})
                        for p in config.cogging_periods
                    ]
                elif name == 'gravity_spring':
                    if j in springs:
                        specs.append(
                            CandidateSpec(
                                name,
                                j,
                                joint,
                                {
                                    'reference_rad': config.gravity_spring_reference_rad,
                                    'degree': config.gravity_spring_degree,
                                },
                            )
                        )
                elif name in ('coulomb_friction', 'load_dependent_friction'):
                    specs.append(CandidateSpec(name, j, joint, {'smoothing_velocity': eps}))
                else:
                    specs.append(CandidateSpec(name, j, joint))
    return specs


def _friction_sign(qs: NominalQuantities, j: Any, settings: Mapping[str, Any]) -> np.ndarray:
    sign: np.ndarray = np.tanh(qs.v[:, j] / settings['smoothing_velocity'])
    return sign


def _gravity_spring(
    qs: NominalQuantities, j: Any, settings: Mapping[str, Any], model: NominalModel
) -> tuple[np.ndarray, ...]:
    dq = qs.q[:, j] - settings['reference_rad']
    return tuple(dq**k for k in range(1, int(settings['degree']) + 1))


def _cogging(
    qs: NominalQuantities, j: Any, settings: Mapping[str, Any], model: NominalModel
) -> tuple[np.ndarray, ...]:
    phase = settings['periods_per_motor_turn'] * model.robot.drives.gear_ratio[j] * qs.q[:, j]
    return np.sin(phase), np.cos(phase)


JointColumns = Callable[
    [NominalQuantities, Any, Mapping[str, Any], NominalModel], tuple[np.ndarray, ...]
]

#: Effects that sit on one joint and act on it alone: their columns as functions of the nominal
#: quantities, the joint index j and the spec's settings. Written with numpy broadcasting, so j
#: may also be an index array with settings arrays of its length: all joints of an effect at once.
JOINT_COLUMNS: dict[str, JointColumns] = {
    'viscous_friction': lambda qs, j, s, model: (qs.v[:, j],),
    'coulomb_friction': lambda qs, j, s, model: (_friction_sign(qs, j, s),),
    'stribeck_friction': lambda qs, j, s, model: (
        np.exp(-((qs.v[:, j] / s['velocity']) ** 2)) * _friction_sign(qs, j, s),
    ),
    'load_dependent_friction': lambda qs, j, s, model: (
        np.abs(qs.tau_rigid[:, j]) * _friction_sign(qs, j, s),
    ),
    'rotor_inertia': lambda qs, j, s, model: (model.robot.drives.gear_ratio[j] ** 2 * qs.a[:, j],),
    'gravity_spring': _gravity_spring,
    'torque_constant_scale': lambda qs, j, s, model: (qs.tau_nominal[:, j],),
    'cogging': _cogging,
    'torque_offset': lambda qs, j, s, model: (np.ones_like(qs.q[:, j]),),
}


def candidate_columns(
    spec: CandidateSpec, quantities: NominalQuantities, model: NominalModel
) -> np.ndarray:
    """The candidate's columns X (N, n, k): the effect adds X @ theta to each joint's tau_u [N*m].

    Raises:
        ValueError: the quantities lack what the effect needs (derivatives, regressor).
    """
    qs = quantities
    n_samples, n = qs.q.shape
    j = spec.joint
    settings = spec.settings

    def on_joint(*columns: np.ndarray) -> np.ndarray:
        out = np.zeros((n_samples, n, len(columns)))
        for c, column in enumerate(columns):
            out[:, j, c] = column
        return out

    name = spec.name
    if name in JOINT_COLUMNS:
        return on_joint(*JOINT_COLUMNS[name](qs, j, settings, model))
    if name == 'joint_offset':
        if qs.dtau_dq is None:
            raise ValueError('joint_offset needs quantities evaluated with derivatives=True')
        return qs.dtau_dq[:, :, j : j + 1].copy()
    if name == 'signal_delay':
        # Currents at t belong to the motion at t - d: tau(t - d) ~ tau(t) - d dtau/dt.
        return -model.nominal_rate(qs)[:, :, None]
    if name == 'payload_mass':
        if qs.regressor is None:
            raise ValueError('payload_mass needs quantities evaluated with regressor=True')
        body, mapping = model.payload_map(str(settings['frame']), settings['com_guess_m'])
        block = qs.regressor[
            :, :, N_INERTIAL_PARAMETERS * body : N_INERTIAL_PARAMETERS * (body + 1)
        ]
        return block @ mapping
    if name == 'inertial_parameter_error':
        if qs.regressor is None:
            raise ValueError('inertial_parameter_error needs quantities with regressor=True')
        return qs.regressor @ np.asarray(settings['base_directions'])
    raise ValueError(f'unknown effect {name!r}')


def needs_derivatives(specs: list[CandidateSpec]) -> bool:
    """Whether any candidate needs d tau / d q, d tau / d v or M(q)."""
    return any(spec.name in ('joint_offset', 'signal_delay') for spec in specs)


def needs_regressor(specs: list[CandidateSpec]) -> bool:
    """Whether any candidate needs the inertial-parameter regressor."""
    return any(spec.name in ('payload_mass', 'inertial_parameter_error') for spec in specs)


# -- testability and plausibility -----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ExcitationFacts:
    """What the (training) excitation and the filter allow; arrays (N, n).

    Attributes:
        v: filtered joint velocities [rad/s].
        cutoff_hz: (n,) cut-offs [Hz].
        column_norm: effective-weighted norm of each filtered column (k,), per candidate label.
        retention: share of a candidate's column energy the filter keeps, per label.
    """

    v: np.ndarray
    cutoff_hz: np.ndarray
    column_norm: dict[str, np.ndarray]
    retention: dict[str, float]


def _moving(v: np.ndarray, eps: float) -> np.ndarray:
    return np.abs(v) > 2.0 * eps


def testability(
    spec: CandidateSpec, facts: ExcitationFacts, model: NominalModel, config: DiagnosisConfig
) -> tuple[bool, str]:
    """Whether this excitation can show the effect at all; the reason when it cannot."""
    robot = model.robot
    j = spec.joint
    eps = config.smoothing_velocity
    norm = facts.column_norm[spec.label]
    if not np.any(norm > 0):
        return False, 'its regressor is zero on this recording'
    if j is not None and spec.name in (
        'viscous_friction',
        'coulomb_friction',
        'stribeck_friction',
        'load_dependent_friction',
        'cogging',
        'rotor_inertia',
    ):
        v = facts.v[:, j]
        moving = _moving(v, eps)
        if moving.mean() < config.min_moving_fraction:
            return False, (
                f'{spec.joint_name} moves (|v| > {2 * eps:g} rad/s) in only '
                f'{100 * moving.mean():.0f} % of the samples'
            )
        if spec.name not in ('rotor_inertia', 'viscous_friction'):
            both = min(np.mean(v > 2 * eps), np.mean(v < -2 * eps))
            if both < 0.25 * config.min_moving_fraction:
                return False, f'{spec.joint_name} hardly moves in both directions'
        if spec.name == 'stribeck_friction':
            vs = spec.settings['velocity']
            slow = moving & (np.abs(v) < vs)
            share = slow.sum() / max(moving.sum(), 1)
            if share < config.min_slow_fraction:
                return False, (
                    f'too little slow motion: {100 * share:.1f} % of the moving samples of '
                    f'{spec.joint_name} are slower than v_s = {vs:g} rad/s '
                    f'(needs {100 * config.min_slow_fraction:g} %)'
                )
        if spec.name == 'cogging':
            p = spec.settings['periods_per_motor_turn']
            frequency = p * robot.drives.gear_ratio[j] * np.abs(v[moving]) / (2 * math.pi)
            share = float(np.mean(frequency < facts.cutoff_hz[j]))
            if share < config.min_below_cutoff_fraction:
                return False, (
                    f'above the filter cut-off: its frequency p N |v| / (2 pi) is below the '
                    f'{facts.cutoff_hz[j]:g} Hz cut-off in only {100 * share:.1f} % of the moving '
                    f'samples of {spec.joint_name}'
                )
    retention = facts.retention[spec.label]
    if retention < config.min_retention:
        return False, (
            f'above the filter cut-off: the filter keeps only {100 * retention:.1f} % of its '
            'signature'
        )
    if spec.name in ('joint_offset', 'signal_delay'):
        bound = _single_parameter_bound(spec, model)
        smallest = 5.0 / float(norm[0])  # 5 standard errors from zero, noise only
        if smallest > bound:
            unit = PARAMETERS[spec.name][0][1]
            return False, (
                f'too weak on this excitation: the smallest detectable value {smallest:.3g} '
                f'{unit} exceeds the plausible bound {bound:.3g} {unit}'
            )
    return True, ''


def _single_parameter_bound(spec: CandidateSpec, model: NominalModel) -> float:
    if spec.name == 'joint_offset':
        return 0.02  # rad: an encoder zero error beyond ~1 degree is a calibration failure
    if spec.name == 'signal_delay':
        return max(0.05, 10.0 * model.robot.ipo_period_s)  # s
    raise ValueError(spec.name)


@dataclass(frozen=True, eq=False)
class PlausibilityFacts:
    """Nominal torque levels the size rules compare against; (n,) arrays [N*m].

    Attributes:
        rigid_rms: RMS of the URDF rigid-body torque per joint.
        gravity: (N, n) nominal gravity torque along the training motion (for the spring's sign).
        moving_mass_kg: total moving mass of the URDF [kg].
        body_parameters: (bodies, 10) the URDF's inertial parameters (pinocchio's order).
    """

    rigid_rms: np.ndarray
    gravity: np.ndarray
    moving_mass_kg: float
    body_parameters: np.ndarray


def plausibility(
    spec: CandidateSpec,
    theta: np.ndarray,
    contribution: np.ndarray,
    model: NominalModel,
    facts: PlausibilityFacts,
    *,
    covariance: np.ndarray | None = None,
) -> tuple[bool, str]:
    """Whether a fitted value is physically plausible; the reason when it is not.

    A value is implausible when it lies outside the plausible range by more than its
    simultaneous 95 % confidence margin: sqrt(chi^2_k(0.95)) standard errors for a group of k
    parameters (1.96 for one), so a weakly determined value is not condemned for its noise.

    Args:
        spec: the candidate.
        theta: (k,) its parameters in physical units.
        contribution: (N, n) the torque it adds along the training motion [N*m] (unfiltered).
        model: the nominal model (robot limits, drives).
        facts: nominal torque levels.
        covariance: (k, k) covariance of theta; exact values if None.
    """
    robot = model.robot
    j = spec.joint
    limit = robot.limits.torque[j] if j is not None else None
    k = len(theta)
    covariance = np.zeros((k, k)) if covariance is None else np.asarray(covariance)
    sd = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    margin = math.sqrt(float(stats.chi2.ppf(0.95, k)))
    value = float(theta[0])
    name = spec.name

    def _in_range(value: float, low: float, high: float, unit: str) -> tuple[bool, str]:
        return _within(value, margin * float(sd[0]), low, high, unit)

    if name == 'viscous_friction':
        assert limit is not None
        assert j is not None
        bound = limit / robot.limits.velocity[j]
        return _in_range(value, 0.0, bound, 'N*m*s/rad')
    if name in ('coulomb_friction', 'stribeck_friction'):
        assert limit is not None
        return _in_range(value, 0.0, 0.5 * limit, 'N*m')
    if name == 'load_dependent_friction':
        return _in_range(value, 0.0, 0.5, '')
    if name == 'rotor_inertia':
        assert j is not None
        nominal = robot.drives.rotor_inertia[j]
        # A brake or gear stage adds inertia; a datasheet is rarely off by more than 3x.
        low = -0.9 * nominal if nominal > 0 else 0.0
        high = 3.0 * nominal if nominal > 0 else 1e-3
        return _in_range(value, low, high, 'kg*m^2')
    if name == 'gravity_spring':
        assert j is not None
        spring = contribution[:, j]
        gravity = facts.gravity[:, j]
        if np.std(spring) == 0 or np.std(gravity) == 0:
            return False, 'no gravity torque to balance'
        correlation = float(np.corrcoef(spring, gravity)[0, 1])
        if correlation >= 0:
            return False, f'it would add to gravity (correlation {correlation:+.2f}), not balance'
        if np.sqrt(np.mean(spring**2)) > 1.5 * np.sqrt(np.mean(gravity**2)):
            return False, 'it would exceed 1.5 times the gravity torque it balances'
        return True, ''
    if name == 'payload_mass':
        mass = value
        if not (mass + margin * sd[0] > 0.0 and mass - margin * sd[0] <= facts.moving_mass_kg):
            return False, (
                f'mass {mass:.3g} kg outside (0, {facts.moving_mass_kg:.3g}] kg (moving mass)'
            )
        com = np.asarray(theta[1:4]) / mass
        if np.linalg.norm(com) > 1.0:
            return False, f'centre of mass {np.linalg.norm(com):.2f} m from the frame (> 1 m)'
        return True, ''
    if name == 'joint_offset':
        bound = _single_parameter_bound(spec, model)
        return _in_range(value, -bound, bound, 'rad')
    if name == 'torque_constant_scale':
        return _in_range(value, -0.3, 0.3, '')
    if name == 'signal_delay':
        return _in_range(value, 0.0, _single_parameter_bound(spec, model), 's')
    if name == 'cogging':
        assert limit is not None
        amplitude = float(np.hypot(theta[0], theta[1]))
        spread = margin * float(np.hypot(sd[0], sd[1]))
        return _within(amplitude, spread, 0.0, 0.05 * limit, 'N*m amplitude')
    if name == 'torque_offset':
        assert limit is not None
        return _in_range(value, -0.1 * limit, 0.1 * limit, 'N*m')
    if name == 'inertial_parameter_error':
        return _plausible_inertial_change(spec, theta, covariance, facts, margin)
    raise ValueError(f'unknown effect {name!r}')


def _plausible_inertial_change(
    spec: CandidateSpec,
    theta: np.ndarray,
    covariance: np.ndarray,
    facts: PlausibilityFacts,
    margin: float,
) -> tuple[bool, str]:
    """CAD-derived link data are off by tens of per cent at most, not by the whole link.

    Bounds on the change of each body's parameters: mass 15 % + 0.5 kg; first moment 10 % + 3 cm
    times the mass; inertia about the joint frame 20 % (Frobenius norm) + the mass times
    (5 cm)^2; each beyond ``margin`` standard errors. The data fix only the identifiable
    combinations, so the change judged is the most plausible one that produces the same
    torques: the fitted change plus the null-space shift that minimises its size relative to
    these bounds.
    """
    directions = np.asarray(spec.settings['base_directions'])
    null = np.asarray(spec.settings.get('null_directions', np.zeros((len(directions), 0))))
    bounds = np.concatenate([_body_bounds(nominal) for nominal in facts.body_parameters])
    weight = 1.0 / bounds
    mapping = directions
    if null.shape[1]:
        # min_z |W (D theta + N z)|: project D theta off the weighted null space.
        weighted_null = weight[:, None] * null
        shift, *_ = np.linalg.lstsq(weighted_null, -(weight[:, None] * directions), rcond=None)
        mapping = directions + null @ shift
    change_all = mapping @ np.asarray(theta)
    covariance_all = mapping @ covariance @ mapping.T
    for body, nominal in enumerate(facts.body_parameters):
        rows = slice(N_INERTIAL_PARAMETERS * body, N_INERTIAL_PARAMETERS * (body + 1))
        ok, reason = _plausible_body_change(
            change_all[rows], covariance_all[rows, rows], nominal, margin
        )
        if not ok:
            return False, f'body {body + 1}: {reason}'
    return True, ''


def _body_limits(nominal: np.ndarray) -> tuple[float, float, float]:
    """Plausible change of a body's mass [kg], first moment [kg*m], inertia [kg*m^2]."""
    mass = float(nominal[0])
    return (
        0.15 * mass + 0.5,
        0.1 * float(np.linalg.norm(nominal[1:4])) + 0.03 * mass,
        0.2 * float(np.linalg.norm(nominal[4:])) + mass * 0.05**2,
    )


def _body_bounds(nominal: np.ndarray) -> np.ndarray:
    """The limits spread over the 10 parameters (vector parts share their norm's limit)."""
    mass, first, inertia = _body_limits(nominal)
    return np.array([mass, *[first / math.sqrt(3)] * 3, *[inertia / math.sqrt(6)] * 6])


def _plausible_body_change(
    change: np.ndarray, change_covariance: np.ndarray, nominal: np.ndarray, margin: float
) -> tuple[bool, str]:
    mass_limit, first_limit, inertia_limit = _body_limits(nominal)
    checks = (
        ('mass', slice(0, 1), mass_limit, 'kg'),
        ('first moment', slice(1, 4), first_limit, 'kg*m'),
        ('inertia', slice(4, 10), inertia_limit, 'kg*m^2'),
    )
    for what, part, bound, unit in checks:
        vector = change[part]
        size = float(np.linalg.norm(vector))
        # Standard error of the size along the change's own direction.
        direction = vector / size if size > 0 else vector
        spread = float(np.sqrt(max(direction @ change_covariance[part, part] @ direction, 0.0)))
        if size - margin * spread > bound:
            return False, (
                f'the {what} of the link would change by {size:.3g} {unit}, more than a '
                f'plausible data error ({bound:.3g} {unit})'
            )
    return True, ''


def _within(value: float, spread: float, low: float, high: float, unit: str) -> tuple[bool, str]:
    if value + spread >= low and value - spread <= high:
        return True, ''
    return False, (
        f'value {value:.4g} +- {spread:.2g} {unit} outside the plausible range '
        f'[{low:.4g}, {high:.4g}]'
    )


# -- parameters for the report ------------------------------------------------------------------
def describe_parameters(
    spec: CandidateSpec,
    theta: np.ndarray,
    half_width: np.ndarray,
    model: NominalModel,
) -> list[dict[str, Any]]:
    """Physical parameters with confidence intervals, in the twin's terms where one exists.

    Args:
        spec: the candidate.
        theta: (k,) fitted column coefficients in physical units.
        half_width: (k,) half widths of their confidence intervals (same units).
        model: the nominal model (datasheet values for scales).

    Returns:
        One dict per parameter: name, value, ci (low, high), unit.
    """
    robot = model.robot
    j = spec.joint

    def entry(name: str, value: float, low: float, high: float, unit: str) -> dict[str, Any]:
        return {
            'name': name,
            'value': float(value),
            'ci': [float(min(low, high)), float(max(low, high))],
            'unit': unit,
        }

    lo, hi = theta - half_width, theta + half_width
    name = spec.name
    if name == 'inertial_parameter_error':
        return [
            {
                'name': 'base_parameter_changes',
                'value': len(theta),
                'ci': None,
                'unit': 'count (directions of the identifiable inertial parameters)',
            }
        ]
    if name == 'rotor_inertia' and j is not None:
        nominal = robot.drives.rotor_inertia[j]
        out = [entry('rotor_inertia_motor_side', nominal + theta[0], nominal + lo[0],
                     nominal + hi[0], 'kg*m^2')]  # fmt: skip
        if nominal > 0:
            out.append(
                entry(
                    'scale',
                    1 + theta[0] / nominal,
                    1 + lo[0] / nominal,
                    1 + hi[0] / nominal,
                    '1',
                )
            )
        return out
    if name == 'torque_constant_scale':
        # tau_u from currents = tau_true / s, so the column gain is c = 1 / s - 1.
        def scale(c: float) -> float:
            return 1.0 / (1.0 + c) if c > -1 else math.inf

        return [entry('scale', scale(theta[0]), scale(hi[0]), scale(lo[0]), '1')]
    if name == 'cogging':
        amplitude = float(np.hypot(theta[0], theta[1]))
        spread = float(np.hypot(half_width[0], half_width[1]))
        return [
            entry('amplitude', amplitude, max(amplitude - spread, 0.0), amplitude + spread, 'N*m'),
            entry(
                'phase', math.atan2(theta[1], theta[0]), -math.pi, math.pi, 'rad'
            ),  # phase interval is not meaningful near zero amplitude
        ]
    if name == 'payload_mass':
        mass = float(theta[0])
        out = [entry('mass', mass, lo[0], hi[0], 'kg')]
        if mass > 0:
            for axis, k in zip('xyz', range(1, 4), strict=True):
                com = theta[k] / mass
                spread = abs(com) * math.hypot(half_width[k] / max(abs(theta[k]), 1e-12),
                                               half_width[0] / mass)  # fmt: skip
                out.append(entry(f'com_{axis}', com, com - spread, com + spread, 'm'))
        return out
    if name == 'stribeck_friction':
        return [
            entry('level', theta[0], lo[0], hi[0], 'N*m'),
            entry(
                'velocity',
                spec.settings['velocity'],
                spec.settings['velocity'],
                spec.settings['velocity'],
                'rad/s',
            ),
        ]
    if name == 'gravity_spring':
        unit = {1: 'N*m/rad'}
        return [
            entry(f'c{k}', theta[k - 1], lo[k - 1], hi[k - 1], unit.get(k, f'N*m/rad^{k}'))
            for k in range(1, len(theta) + 1)
        ]
    names = PARAMETERS[name]
    return [entry(names[k][0], theta[k], lo[k], hi[k], names[k][1]) for k in range(len(theta))]
