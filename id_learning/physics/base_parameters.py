"""Base inertial parameters, physical consistency and the CAD prior of a robot's bodies.

Joint torques depend on the bodies' inertial parameters theta (pinocchio's 10 per body: m, m c,
inertia about the body frame) only through a smaller set of combinations, the base parameters
beta = E theta (Khalil and Dombre): some parameters never act (a body rotating about a fixed
vertical axis shows no mass), others act only together (masses carried along a chain). The
identification estimates theta whole, kept physical (each body's pseudo-inertia positive
semidefinite: Wensing, Kim and Slotine 2017) and drawn towards the CAD model (the URDF), so that
the directions the recording does not reach stay at the URDF's values; the base parameters are
what it reports.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS, RigidBodyDynamics
from id_learning.robot.config import JointLimits

__all__ = [
    'PARAMETER_NAMES',
    'BaseParameters',
    'CadPrior',
    'base_parameters',
    'pseudo_inertia',
    'pseudo_inertia_basis',
]

#: pinocchio's order of a body's 10 dynamic parameters (inertia about the body frame's origin).
PARAMETER_NAMES = ('m', 'mcx', 'mcy', 'mcz', 'Ixx', 'Ixy', 'Iyy', 'Ixz', 'Iyz', 'Izz')
#: Units of PARAMETER_NAMES.
PARAMETER_UNITS = ('kg', 'kg*m', 'kg*m', 'kg*m', *['kg*m^2'] * 6)


@dataclass(frozen=True, eq=False)
class BaseParameters:
    """The identifiable combinations of a robot's inertial parameters.

    Attributes:
        matrix: (r, 10 B) E with beta = E theta; Y(q, v, a) theta = Y_base beta for every state.
        independent: (r,) indices of the parameters each base parameter is named after.
        names: (r,) readable names, e.g. 'body 2 mcx (+3 grouped)'.
        units: (r,) units of each base parameter.
    """

    matrix: np.ndarray
    independent: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]

    @property
    def count(self) -> int:
        """r, the number of base parameters."""
        return int(self.matrix.shape[0])


def base_parameters(
    dynamics: RigidBodyDynamics, limits: JointLimits, n_states: int = 400
) -> BaseParameters:
    """Base parameters by QR with column pivoting of the regressor on random states.

    States are drawn inside the joint limits (fixed seed: the result belongs to the robot). The
    first r pivoted columns are independent; every other column is a fixed combination of them,
    which E folds in: beta = theta_B + K theta_D with K = R_BB^-1 R_BD.
    """
    rng = np.random.default_rng(20260102)
    n = dynamics.n_joints
    q = rng.uniform(limits.position_lower, limits.position_upper, size=(n_states, n))
    v = rng.uniform(-1.0, 1.0, size=(n_states, n)) * limits.velocity
    a = rng.uniform(-1.0, 1.0, size=(n_states, n)) * limits.acceleration
    y = dynamics.regressor(q, v, a).reshape(n_states * n, -1)
    norms = np.linalg.norm(y, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    _, r, pivots = linalg.qr(y / scale, mode='economic', pivoting=True)
    diagonal = np.abs(np.diag(r))
    rank = int(np.sum(diagonal > 1e-8 * diagonal[0]))
    independent, dependent = pivots[:rank], pivots[rank:]
    # In scaled units: y_D = y_B K; back in physical units K_phys = diag(1/s_B) K diag(s_D).
    k_scaled = linalg.solve_triangular(r[:rank, :rank], r[:rank, rank:])
    k = k_scaled * scale[dependent][None, :] / scale[independent][:, None]
    matrix = np.zeros((rank, y.shape[1]))
    matrix[np.arange(rank), independent] = 1.0
    matrix[:, dependent] = k
    names, units = [], []
    for row, column in zip(matrix, independent, strict=True):
        grouped = int(np.sum(np.abs(row) > 1e-10)) - 1
        body, index = divmod(int(column), N_INERTIAL_PARAMETERS)
        names.append(
            f'body {body + 1} {PARAMETER_NAMES[index]}'
            + (f' (+{grouped} grouped)' if grouped else '')
        )
        units.append(PARAMETER_UNITS[index])
    return BaseParameters(matrix, independent, tuple(names), tuple(units))


def pseudo_inertia_basis() -> np.ndarray:
    """(10, 4, 4) matrices B_k with J(theta_body) = sum_k theta_k B_k.

    The pseudo-inertia J = [[Sigma, h], [h^T, m]] with Sigma = tr(I) / 2 * 1 - I the second
    moment of the mass distribution about the body frame's origin (I the inertia there, h = m c).
    J is positive semidefinite exactly when the parameters belong to some real mass distribution.
    """
    basis = np.zeros((N_INERTIAL_PARAMETERS, 4, 4))
    basis[0, 3, 3] = 1.0
    for axis in range(3):
        basis[1 + axis, axis, 3] = basis[1 + axis, 3, axis] = 1.0
    # Inertia entries in pinocchio's order xx, xy, yy, xz, yz, zz: (row, column) of I.
    entries = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))
    for k, (i, j) in enumerate(entries):
        unit = np.zeros((3, 3))
        unit[i, j] = unit[j, i] = 1.0
        sigma = 0.5 * np.trace(unit) * np.eye(3) - unit
        basis[4 + k, :3, :3] = sigma
    return basis


def pseudo_inertia(theta_body: np.ndarray) -> np.ndarray:
    """The 4x4 pseudo-inertia of one body's 10 parameters."""
    return np.tensordot(np.asarray(theta_body, dtype=float), pseudo_inertia_basis(), axes=1)


@dataclass(frozen=True, eq=False)
class CadPrior:
    """How far a CAD model's (URDF's) inertial parameters are trusted: one std per parameter.

    Attributes:
        mass_rel: relative std of a body's mass.
        mass_abs_kg: absolute std added to it [kg] (cables, screws, fluids).
        first_moment_rel: relative std of a body's first moment m c.
        com_abs_m: std of its centre of mass position, times its mass [m].
        inertia_rel: relative std of its inertia (Frobenius norm of the 3x3 tensor).
        inertia_radius_m: std of a radius of gyration, as m r^2 added to the inertia [m].
    """

    mass_rel: float = 0.10
    mass_abs_kg: float = 0.5
    first_moment_rel: float = 0.10
    com_abs_m: float = 0.03
    inertia_rel: float = 0.20
    inertia_radius_m: float = 0.05

    def std(self, theta: np.ndarray) -> np.ndarray:
        """(10 B,) prior standard deviations around the URDF's parameters theta (10 B,)."""
        out = []
        for body in np.asarray(theta, dtype=float).reshape(-1, N_INERTIAL_PARAMETERS):
            mass = abs(body[0])
            first = self.first_moment_rel * float(np.linalg.norm(body[1:4]))
            first += self.com_abs_m * mass
            inertia = self.inertia_rel * float(np.linalg.norm(body[4:]))
            inertia += mass * self.inertia_radius_m**2
            out.append(
                [
                    self.mass_rel * mass + self.mass_abs_kg,
                    *[max(first, 1e-6)] * 3,
                    *[max(inertia, 1e-6)] * 6,
                ]
            )
        return np.concatenate(out)
