"""The nominal model: the URDF's rigid-body dynamics plus the datasheet drives.

    tau_nominal = RNEA(q, v, a) + J_m N^2 a        (motor target; RNEA only for joint torques)

``NominalModel.evaluate`` gives the quantities that effect terms are built from along a motion:
the nominal torques, optionally their derivatives, the mass matrix and the inertial-parameter
regressor.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from id_learning.physics.inertial import frame_parameter_map, payload_parameter_map
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_inertia_joint_side, rotor_inertia_torque

__all__ = ['NominalModel', 'NominalQuantities']


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
        tau_gravity: g(q) of the URDF [N*m], or None (quantities built without it).
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
    tau_gravity: np.ndarray | None = None


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
        self._payload_maps: dict[tuple[str, tuple[float, ...], bool], tuple[int, np.ndarray]] = {}

    def payload_map(
        self, frame: str, com_guess_m: Sequence[float], inertia: bool = False
    ) -> tuple[int, np.ndarray]:
        """``payload_parameter_map`` of this model, computed once per frame and COM guess.

        ``inertia``: six more columns, the payload's rotational inertia about its centre of mass
        in the frame's axes (xx, xy, yy, xz, yz, zz), for a body that is no point mass.
        """
        key = (frame, tuple(float(x) for x in com_guess_m), bool(inertia))
        if key not in self._payload_maps:
            body, mapping = payload_parameter_map(self.dynamics, frame, np.asarray(key[1]))
            if inertia:
                mapping = np.hstack([mapping, frame_parameter_map(self.dynamics, frame)[1][:, 4:]])
            self._payload_maps[key] = (body, mapping)
        return self._payload_maps[key]

    @property
    def rotor_inertia_joint_side(self) -> np.ndarray:
        """(n,) J_m N^2 [kg*m^2]; zero when the target is the joint torque."""
        drives = self.robot.drives
        if self.target != 'motor':
            return np.zeros(self.robot.n_joints)
        return rotor_inertia_joint_side(drives.rotor_inertia, drives.gear_ratio)

    def sample_function(self) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """tau_nominal of one sample, (n,) q, v, a -> (n,) [N*m], with its own pinocchio data."""
        rnea, rotor = self.dynamics.sample_rnea(), self.rotor_inertia_joint_side

        def tau_nominal(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = rnea(q, v, a) + rotor * a
            return tau

        return tau_nominal

    def evaluate(
        self,
        q: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        jerk: np.ndarray | None = None,
        *,
        derivatives: bool = False,
        regressor: bool = False,
        gravity: bool = False,
    ) -> NominalQuantities:
        """Evaluate the nominal model along a motion.

        Args:
            q: (N, n) joint positions [rad].
            v: (N, n) joint velocities [rad/s].
            a: (N, n) joint accelerations [rad/s^2].
            jerk: (N, n) joint jerks [rad/s^3]; zero if None.
            derivatives: also compute d tau / d q, d tau / d v and M(q).
            regressor: also compute the inertial-parameter regressor.
            gravity: also compute g(q) (friction growing with gravity's torque reads it).
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
            tau_gravity=self.dynamics.gravity(q) if gravity else None,
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
        rate: np.ndarray = (
            np.einsum('bij,bj->bi', quantities.dtau_dq, quantities.v)
            + np.einsum('bij,bj->bi', quantities.dtau_dv, quantities.a)
            + np.einsum('bij,bj->bi', inertia, quantities.jerk)
        )
        return rate
