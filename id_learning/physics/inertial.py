"""Inertial-parameter algebra of rigid bodies: frames, payloads, identifiable directions.

A body's dynamic parameters are pinocchio's 10-vector: mass m, first moment h = m c (3) and the
inertia about the body frame's origin (6: xx, xy, yy, xz, yz, zz). Everything here is linear in
that vector, so it maps regressor columns as well as parameters.
"""

from __future__ import annotations

import numpy as np

from id_learning.physics.rigid_body import RigidBodyDynamics, frame_id
from id_learning.robot.config import JointLimits

__all__ = [
    'frame_parameter_map',
    'inertial_base_directions',
    'payload_parameter_map',
    'transform_dynamic_parameters',
]


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
    dynamics: RigidBodyDynamics, frame: str, com_guess_m: np.ndarray
) -> tuple[int, np.ndarray]:
    """Map a point-mass payload's (m, h = m c) in ``frame`` to its parent body's 10 parameters.

    A point mass has inertia S(h)^T S(h) / m about the frame origin: quadratic in h. Linearised at
    the COM guess c0 (exact when h = m c0) it is -m S(c0)^T S(c0) + S(h)^T S(c0) + S(c0)^T S(h);
    refitting with c0 = h / m converges to the point mass.

    Returns:
        (body index into the regressor's bodies, (10, 4) map from (m, h_x, h_y, h_z)).
    """
    pin_model = dynamics.model
    index = frame_id(pin_model, frame, 'payload frame')
    placement = pin_model.frames[index].placement
    parent = int(pin_model.frames[index].parentJoint)
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
    dynamics: RigidBodyDynamics, limits: JointLimits, n_states: int = 400
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
    rng = np.random.default_rng(20260101)
    n = dynamics.n_joints
    q = rng.uniform(limits.position_lower, limits.position_upper, size=(n_states, n))
    v = rng.uniform(-1.0, 1.0, size=(n_states, n)) * limits.velocity
    a = rng.uniform(-1.0, 1.0, size=(n_states, n)) * limits.acceleration
    y = dynamics.regressor(q, v, a).reshape(n_states * n, -1)
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


def frame_parameter_map(dynamics: RigidBodyDynamics, frame: str) -> tuple[int, np.ndarray]:
    """Map a body's 10 parameters expressed in ``frame`` onto its parent body's (a payload).

    Returns:
        (body index into the regressor's bodies, (10, 10) map T: theta_parent += T theta_frame).

    Raises:
        RobotModelError: the frame does not exist.
    """
    pin_model = dynamics.model
    index = frame_id(pin_model, frame)
    placement = pin_model.frames[index].placement
    parent = int(pin_model.frames[index].parentJoint)
    columns = [
        transform_dynamic_parameters(unit, placement.rotation, placement.translation)
        for unit in np.eye(10)
    ]
    return parent - 1, np.array(columns).T
