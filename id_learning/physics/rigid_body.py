"""Rigid-body dynamics of a robot config through pinocchio, batched over samples.

Arrays follow the config's joint order, whatever order pinocchio builds the tree in:
q: (..., n) [rad], v: (..., n) [rad/s], a: (..., n) [rad/s^2], tau: (..., n) [N*m] joint side.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from id_learning.errors import RobotModelError
from id_learning.robot.config import RobotConfig
from id_learning.robot.urdf_checks import check_urdf
from id_learning.robot.urdf_inertials import parse_urdf

__all__ = ['IMPLAUSIBLE_LOAD', 'RigidBodyDynamics', 'build_pinocchio_model']

N_INERTIAL_PARAMETERS = 10  # m, m*c (3), inertia at the joint frame (6): pinocchio's order
#: A joint whose gravity torque, or whose torque to accelerate its own inertia at its limit
#: acceleration, exceeds its torque limit this many times cannot be the robot: no drive holds
#: it, so a mass or an inertia of the URDF is off (a unit, a typo). The shipped arms reach 0.65
#: at most (the Panda's joint_2 holding the arm out).
IMPLAUSIBLE_LOAD = 100.0
#: Poses, drawn across the config's joint ranges, at which the loads are weighed.
LOAD_POSES = 64


def build_pinocchio_model(config: RobotConfig) -> pin.Model:
    """Build the pinocchio model of the config's URDF, locking the config's locked joints.

    Raises:
        RobotModelError: the URDF cannot be parsed or cannot be the robot
            (``urdf_checks.check_urdf``), its movable joints differ from the config, or its
            masses load a joint beyond ``IMPLAUSIBLE_LOAD`` times its torque limit.
    """
    check_urdf(config.urdf_path, config.joints, config.locked_joints, config.source)
    try:
        renamed = _unique_frame_names(config.urdf_path)
        full = (
            pin.buildModelFromUrdf(str(config.urdf_path))
            if renamed is None
            else pin.buildModelFromXML(renamed)
        )
    except (RuntimeError, ValueError) as err:
        raise RobotModelError(
            f'{config.urdf_path}: cannot build a model from the URDF: {err}'
        ) from err
    urdf_joints = list(full.names[1:])
    missing = [name for name in config.joints if name not in urdf_joints]
    unknown_locked = [name for name in config.locked_joints if name not in urdf_joints]
    if missing or unknown_locked:
        raise RobotModelError(
            f'{config.urdf_path}: the URDF has no joint(s) {missing + unknown_locked} '
            'named in the '
            f'robot config {config.source or ""}; URDF movable joints: {urdf_joints}'
        )
    extra = [
        name
        for name in urdf_joints
        if name not in config.joints and name not in config.locked_joints
    ]
    if extra:
        raise RobotModelError(
            f"{config.urdf_path}: movable URDF joint(s) {extra} are neither in the robot config's "
            f'joints nor in its locked_joints {config.source or ""}'
        )
    if not config.locked_joints:
        model = full
    else:
        reference = pin.neutral(full)
        lock_ids = []
        for name, value in config.locked_joints.items():
            joint_id = full.getJointId(name)
            joint = full.joints[joint_id]
            if joint.nq != 1:
                raise RobotModelError(
                    f'{config.urdf_path}: locked joint {name} is not a 1-DoF joint'
                )
            reference[joint.idx_q] = value
            lock_ids.append(joint_id)
        model = pin.buildReducedModel(full, lock_ids, reference)
    for name in config.joints:
        joint = model.joints[model.getJointId(name)]
        if joint.nq != 1 or joint.nv != 1:
            raise RobotModelError(
                f'{config.urdf_path}: joint {name} has {joint.nq} position coordinates; '
                'only 1-DoF revolute or prismatic joints are supported '
                '(declare continuous joints as revolute)'
            )
    _check_limits_against_urdf(model, config)
    if not model.existFrame(config.payload_frame):
        raise RobotModelError(
            f'{config.urdf_path}: payload_frame {config.payload_frame!r} is not a URDF frame'
        )
    _check_loads(model, config)
    return model


def _check_loads(model: pin.Model, config: RobotConfig) -> None:
    """Refuse masses or inertias that load a joint beyond ``IMPLAUSIBLE_LOAD`` x its torque limit.

    The loads are weighed at ``LOAD_POSES`` fixed poses across the joint ranges: the gravity
    torque, and the torque that accelerates the joint's own inertia (the mass matrix' diagonal)
    at its limit acceleration. The torque limit is the URDF's effort where it gives one (the
    vendor's figure beside its masses), else the config's.
    """
    joint_ids = [model.getJointId(name) for name in config.joints]
    index_q = [model.joints[j].idx_q for j in joint_ids]
    index_v = [model.joints[j].idx_v for j in joint_ids]
    urdf_effort = np.asarray(model.effortLimit)[index_v]
    from_urdf = np.isfinite(urdf_effort) & (urdf_effort > 0)
    reference = np.where(from_urdf, urdf_effort, config.limits.torque)
    lower, upper = config.limits.position_lower, config.limits.position_upper
    poses = np.vstack(
        [
            np.clip(0.0, lower, upper),
            np.random.default_rng(0).uniform(lower, upper, (LOAD_POSES - 1, len(lower))),
        ]
    )
    data, q = model.createData(), pin.neutral(model)
    # The worst (ratio, joint, load, pose) of each kind; gravity is said first, being plainer.
    worst: dict[str, tuple[float, int, float, np.ndarray]] = {}
    with np.errstate(all='ignore'):
        for pose in poses:
            q[index_q] = pose
            gravity = np.abs(pin.computeGeneralizedGravity(model, data, q)[index_v])
            own = np.diag(pin.crba(model, data, q))[index_v] * config.limits.acceleration
            for what, load in (('gravity', gravity), ('inertia', own)):
                ratios = np.where(np.isnan(load), np.inf, load / reference)
                joint = int(np.argmax(ratios))
                if ratios[joint] > max(IMPLAUSIBLE_LOAD, worst.get(what, (0.0,))[0]):
                    worst[what] = (float(ratios[joint]), joint, float(load[joint]), pose)
    if not worst:
        return
    what = 'gravity' if 'gravity' in worst else 'inertia'
    ratio, joint, load, at = worst[what]
    name = config.joints[joint]
    needs = (
        'gravity alone loads it with'
        if what == 'gravity'
        else f'accelerating it at its limit {config.limits.acceleration[joint]:g} rad/s^2 needs'
    )
    limit = 'its URDF effort' if from_urdf[joint] else 'limits.torque of the robot config'
    heaviest, mass = _heaviest_body(model, joint_ids[joint])
    raise RobotModelError(
        f'{config.urdf_path}: joint {name}: {needs} {load:.3g} N*m at q = '
        f'{np.round(at, 2).tolist()} rad, {ratio:.3g} times {limit} {reference[joint]:g} N*m; '
        f'beyond {IMPLAUSIBLE_LOAD:g} times no drive could move the arm, so a mass or an inertia '
        f'of the URDF (kg, kg*m^2) or the limit is off: the heaviest link it moves is '
        f'{heaviest} ({mass:.4g} kg)'
    )


def _heaviest_body(model: pin.Model, joint_id: int) -> tuple[str, float]:
    """The link of the heaviest body that joint ``joint_id`` moves, and that body's mass [kg]."""
    body = max(model.subtrees[joint_id], key=lambda i: model.inertias[i].mass)
    names = [
        frame.name
        for frame in model.frames
        if frame.parentJoint == body and frame.type == pin.FrameType.BODY
    ]
    return (names[0] if names else model.names[body]), float(model.inertias[body].mass)


def frame_id(model: pin.Model, name: str, what: str = 'frame') -> int:
    """The index of the frame ``name``: a link's (BODY) frame first, where a joint shares it.

    Raises:
        RobotModelError: no frame has that name (``what`` says which frame was sought).
    """
    kinds = (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT)
    for kind in (*kinds, pin.FrameType.JOINT, pin.FrameType.SENSOR):
        if model.existFrame(name, kind):
            return int(model.getFrameId(name, kind))
    raise RobotModelError(f'{what} {name!r} does not exist in the URDF')


def _unique_frame_names(urdf: Path | str) -> str | None:
    """The URDF's text with each fixed joint named like a link renamed ``<name>_fixed_joint``.

    None when no joint needs it: the file is then read as it is (ElementTree would rewrite a
    default XML namespace as a prefix that pinocchio's parser does not know).

    Vendor URDFs often name a fixed joint after its child link (``flange``). pinocchio makes a
    frame of each, and then refuses to look either up by name ("Several frames match the
    filter"), also inside ``buildReducedModel``. Fixed joints carry no motion and the config
    never names them: renaming them leaves the dynamics and every name the package uses as they
    were, and the link keeps its name.
    """
    root = parse_urdf(urdf)
    links = {link.get('name') for link in root.iter('link')}
    names = {joint.get('name') for joint in root.iter('joint')} | links
    changed = False
    for joint in root.iter('joint'):
        name = joint.get('name')
        if joint.get('type') == 'fixed' and name in links:
            renamed = f'{name}_fixed_joint'
            while renamed in names:
                renamed += '_'
            joint.set('name', renamed)
            names.add(renamed)
            changed = True
    return ElementTree.tostring(root, encoding='unicode') if changed else None


def _check_limits_against_urdf(model: pin.Model, config: RobotConfig) -> None:
    """Refuse config limits wider than the URDF's (where the URDF states finite limits)."""
    limits = config.limits
    tolerance = 1e-9
    for i, name in enumerate(config.joints):
        index = model.joints[model.getJointId(name)].idx_q
        low, high = model.lowerPositionLimit[index], model.upperPositionLimit[index]
        checks = []
        if np.isfinite(low) and np.isfinite(high) and high > low:
            checks += [
                ('position_lower', limits.position_lower[i] < low - tolerance, low),
                ('position_upper', limits.position_upper[i] > high + tolerance, high),
            ]
        for key, urdf_value in (
            ('velocity', model.velocityLimit[index]),
            ('torque', model.effortLimit[index]),
        ):
            if np.isfinite(urdf_value) and urdf_value > 0:
                checks.append((key, getattr(limits, key)[i] > urdf_value + tolerance, urdf_value))
        for key, exceeded, urdf_value in checks:
            if exceeded:
                raise RobotModelError(
                    f'{config.source or config.name}: limits.{key} of {name} '
                    f'({getattr(limits, key)[i]:g}) lies outside the URDF limit {urdf_value:g} '
                    f'in {config.urdf_path}'
                )


class RigidBodyDynamics:
    """Inverse dynamics, gravity, mass matrix and regressor of one robot, in config joint order.

    The pinocchio model is fixed; scratch data is kept apart and reused between calls.
    """

    def __init__(
        self, model: pin.Model, joints: tuple[str, ...], gravity: np.ndarray | None = None
    ) -> None:
        """Wrap a pinocchio model whose 1-DoF joints are exactly ``joints``."""
        self.model = model.copy()
        if gravity is not None:
            self.model.gravity.linear = np.asarray(gravity, dtype=float)
        self.joints = joints
        names = list(self.model.names[1:])
        if sorted(names) != sorted(joints) or self.model.nv != len(joints):
            raise RobotModelError(
                f'model joints {names} do not match the config joints {list(joints)}'
            )
        self._index = np.array(
            [self.model.joints[self.model.getJointId(name)].idx_v for name in joints]
        )
        self._data = self.model.createData()

    @classmethod
    def from_config(cls, config: RobotConfig) -> RigidBodyDynamics:
        """Build the nominal model from the config's URDF."""
        return cls(build_pinocchio_model(config), config.joints)

    @property
    def n_joints(self) -> int:
        """Number of joints."""
        return len(self.joints)

    @property
    def joint_index(self) -> np.ndarray:
        """(n,) pinocchio's velocity index of each config joint, in config order."""
        return self._index

    @property
    def n_bodies(self) -> int:
        """Number of moving bodies (one per joint)."""
        out: int = self.model.njoints - 1
        return out

    def total_moving_mass(self) -> float:
        """Sum of the moving bodies' masses [kg]."""
        return float(sum(self.model.inertias[i].mass for i in range(1, self.model.njoints)))

    # -- conversions between config order and pinocchio order ------------------------------------
    def _to_pin(self, x: np.ndarray) -> np.ndarray:
        out = np.empty(self.model.nv)
        out[self._index] = x
        return out

    def _batched(
        self, fn: Callable[..., np.ndarray], *arrays: np.ndarray, out_shape: tuple[int, ...]
    ) -> np.ndarray:
        """Apply a per-sample function over arrays of shape (..., n); leading axes are kept."""
        inputs = [np.asarray(x, dtype=float) for x in arrays]
        leading = inputs[0].shape[:-1]
        if any(x.ndim == 0 or x.shape != inputs[0].shape for x in inputs) or (
            inputs[0].shape[-1] != self.n_joints
        ):
            raise ValueError(
                f'expected arrays of one shape (..., {self.n_joints}), '
                f'got {[x.shape for x in inputs]}'
            )
        batch = [x.reshape(-1, self.n_joints) for x in inputs]
        out = np.empty((len(batch[0]), *out_shape))
        for k in range(len(out)):
            out[k] = fn(*[self._to_pin(x[k]) for x in batch])
        return out.reshape(*leading, *out_shape)

    # -- algorithms -------------------------------------------------------------------------------
    def sample_rnea(self) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """``rnea`` of one sample, (n,) q, v, a -> (n,) [N*m], with its own scratch data.

        Calls pinocchio directly when its joint order is the config's (the usual case): ``rnea``
        reshapes and reorders for batches, which costs more than the recursion itself for one
        sample.
        """
        if not np.array_equal(self._index, np.arange(self.n_joints)):
            return self.rnea
        model, data = self.model, self.model.createData()

        def rnea(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            # pinocchio returns a view of data.tau: the caller's arithmetic copies it.
            tau: np.ndarray = pin.rnea(model, data, q, v, a)
            return tau

        return rnea

    def sample_mass_and_bias(
        self,
    ) -> Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """(n,) q, v -> (M(q) (n, n) [kg*m^2], C(q, v) v + g(q) (n,) [N*m]) of one sample.

        What forward dynamics needs each step, in config order, with its own scratch data.
        """
        model, data, ix = self.model, self.model.createData(), self._index

        def mass_and_bias(q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            qp, vp = self._to_pin(q), self._to_pin(v)
            mass = pin.crba(model, data, qp)
            mass = np.triu(mass) + np.triu(mass, 1).T
            bias = pin.nonLinearEffects(model, data, qp, vp)
            return mass[np.ix_(ix, ix)], bias[ix].copy()

        return mass_and_bias

    def rnea(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Joint torques tau = M(q) a + C(q, v) v + g(q) [N*m]; shapes (..., n)."""
        ix = self._index
        return self._batched(
            lambda qk, vk, ak: pin.rnea(self.model, self._data, qk, vk, ak)[ix],
            q,
            v,
            a,
            out_shape=(self.n_joints,),
        )

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """Gravity torques g(q) [N*m]; shape (..., n)."""
        ix = self._index
        return self._batched(
            lambda qk: pin.computeGeneralizedGravity(self.model, self._data, qk)[ix],
            q,
            out_shape=(self.n_joints,),
        )

    def coriolis(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Coriolis and centrifugal torques C(q, v) v [N*m]; shape (..., n)."""
        ix = self._index
        zero = np.zeros(self.model.nv)

        def one(qk: np.ndarray, vk: np.ndarray) -> np.ndarray:
            nle = pin.rnea(self.model, self._data, qk, vk, zero)
            out: np.ndarray = (nle - pin.computeGeneralizedGravity(self.model, self._data, qk))[ix]
            return out

        return self._batched(one, q, v, out_shape=(self.n_joints,))

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space mass matrix M(q) [kg*m^2]; shape (..., n, n)."""
        ix = self._index

        def one(qk: np.ndarray) -> np.ndarray:
            mass = pin.crba(self.model, self._data, qk)
            mass = np.triu(mass) + np.triu(mass, 1).T
            out: np.ndarray = mass[np.ix_(ix, ix)]
            return out

        return self._batched(one, q, out_shape=(self.n_joints, self.n_joints))

    def sample_regressor(
        self, columns: np.ndarray | None = None
    ) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """``regressor`` of one sample, (n,) q, v, a -> (n, k), with its own scratch data.

        ``columns``: the parameters kept (e.g. a base parameter set's independent ones), all if
        None.
        """
        model, data, ix = self.model, self.model.createData(), self._index
        keep = slice(None) if columns is None else np.asarray(columns)

        def regressor(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            full = pin.computeJointTorqueRegressor(
                model, data, self._to_pin(q), self._to_pin(v), self._to_pin(a)
            )
            out: np.ndarray = full[ix][:, keep]
            return out

        return regressor

    def regressor(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque regressor Y with tau = Y @ inertial_parameters(); shape (..., n, 10 * bodies)."""
        ix = self._index
        n_params = N_INERTIAL_PARAMETERS * self.n_bodies
        return self._batched(
            lambda qk, vk, ak: pin.computeJointTorqueRegressor(self.model, self._data, qk, vk, ak)[
                ix
            ],
            q,
            v,
            a,
            out_shape=(self.n_joints, n_params),
        )

    def inertial_parameters(self) -> np.ndarray:
        """Stacked dynamic parameters of every body (pinocchio's order, 10 per body)."""
        return np.concatenate(
            [self.model.inertias[i].toDynamicParameters() for i in range(1, self.model.njoints)]
        )

    # -- variations of the model (the digital twin's "true" robot) --------------------------------
    def with_payload(
        self, frame: str, mass: float, com: np.ndarray, inertia: np.ndarray | None = None
    ) -> RigidBodyDynamics:
        """Return a copy with a rigid payload attached at a frame.

        Args:
            frame: URDF frame name the payload is attached to.
            mass: payload mass [kg].
            com: (3,) payload centre of mass in the frame [m].
            inertia: (3, 3) rotational inertia about the COM [kg*m^2]; a point mass if None.
        """
        model = self.model.copy()
        index = frame_id(model, frame, 'payload frame')
        placement = model.frames[index].placement
        parent = model.frames[index].parentJoint
        rotational = np.zeros((3, 3)) if inertia is None else np.asarray(inertia, dtype=float)
        payload = pin.Inertia(float(mass), np.asarray(com, dtype=float), rotational)
        model.inertias[parent] = model.inertias[parent] + placement.act(payload)
        return RigidBodyDynamics(model, self.joints)

    def with_inertial_parameters(self, parameters: np.ndarray) -> RigidBodyDynamics:
        """Return a copy whose bodies have the given stacked dynamic parameters (10 per body)."""
        model = self.model.copy()
        parameters = np.asarray(parameters, dtype=float).reshape(
            self.n_bodies, N_INERTIAL_PARAMETERS
        )
        for body, values in enumerate(parameters, start=1):
            model.inertias[body] = pin.Inertia.FromDynamicParameters(values)
        return RigidBodyDynamics(model, self.joints)

    def body_masses_and_coms(self) -> tuple[np.ndarray, np.ndarray]:
        """Masses (bodies,) [kg] and centres of mass (bodies, 3) [m] in each joint frame."""
        masses = np.array([self.model.inertias[i].mass for i in range(1, self.model.njoints)])
        coms = np.array(
            [self.model.inertias[i].lever.copy() for i in range(1, self.model.njoints)]
        )
        return masses, coms

    def with_masses_and_coms(self, masses: np.ndarray, coms: np.ndarray) -> RigidBodyDynamics:
        """Return a copy with new body masses and COMs, rotational inertia about the COM kept."""
        model = self.model.copy()
        for body in range(1, model.njoints):
            old = model.inertias[body]
            model.inertias[body] = pin.Inertia(
                float(masses[body - 1]),
                np.asarray(coms[body - 1], dtype=float),
                old.inertia.copy(),
            )
        return RigidBodyDynamics(model, self.joints)
