"""Independent references for the rigid-body tests: pinocchio built straight from the URDF."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from id_learning.robot import RobotConfig

N_STATES = 50
G_WORLD = np.array([0.0, 0.0, -9.81])  # m/s^2, the URDF convention pinocchio follows


def reference_model(config: RobotConfig) -> pin.Model:
    """Build the model straight from the URDF, locking the config's locked joints by hand."""
    full = pin.buildModelFromUrdf(str(config.urdf_path))
    if not config.locked_joints:
        return full
    reference = pin.neutral(full)
    lock_ids = []
    for name, value in config.locked_joints.items():
        joint_id = full.getJointId(name)
        reference[full.joints[joint_id].idx_q] = value
        lock_ids.append(joint_id)
    return pin.buildReducedModel(full, lock_ids, reference)


def velocity_index(model: pin.Model, joints: tuple[str, ...]) -> np.ndarray:
    """Column of each config joint (by name) in the model's q and v vectors (all 1-DoF)."""
    index = []
    for name in joints:
        joint = model.joints[model.getJointId(name)]
        assert joint.idx_q == joint.idx_v  # 1-DoF revolute joints only
        index.append(joint.idx_v)
    return np.array(index)


def random_states(
    config: RobotConfig, rng: np.random.Generator, count: int = N_STATES
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw q, v, a (count, n) uniformly inside the config's limits."""
    limits = config.limits
    shape = (count, config.n_joints)
    q = rng.uniform(limits.position_lower, limits.position_upper, shape)
    v = rng.uniform(-limits.velocity, limits.velocity, shape)
    a = rng.uniform(-limits.acceleration, limits.acceleration, shape)
    return q, v, a


def urdf_axes(urdf_path: Path) -> dict[str, np.ndarray]:
    """Joint axis of every movable URDF joint, in the joint frame (URDF default: x)."""
    axes = {}
    for joint in ET.parse(urdf_path).getroot().findall('joint'):
        if joint.get('type') == 'fixed':
            continue
        axis = joint.find('axis')
        xyz = '1 0 0' if axis is None else axis.get('xyz', '1 0 0')
        vector = np.array([float(x) for x in xyz.split()])
        axes[joint.get('name')] = vector / np.linalg.norm(vector)
    return axes


def world_axes(
    model: pin.Model, data: pin.Data, axes: dict[str, np.ndarray], name: str
) -> tuple[np.ndarray, np.ndarray]:
    """Origin and unit axis in the world of joint ``name`` after forwardKinematics."""
    placement = data.oMi[model.getJointId(name)]
    return placement.translation.copy(), placement.rotation @ axes[name]


def payload_frame_setup(config: RobotConfig) -> tuple[Any, ...]:
    """An independent model, its data, velocity index, URDF axes, the payload frame's id and
    the names of the joints that carry it."""
    model = reference_model(config)
    frame_id = model.getFrameId(config.payload_frame)
    carrying = set()
    joint_id = model.frames[frame_id].parentJoint
    while joint_id > 0:
        carrying.add(model.names[joint_id])
        joint_id = model.parents[joint_id]
    index = velocity_index(model, config.joints)
    return model, model.createData(), index, urdf_axes(config.urdf_path), frame_id, carrying
