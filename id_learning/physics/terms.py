"""Effect terms: named groups of regressor columns that the nominal model lacks.

Each term is one of the stable effect names (the twin's) on one joint, or robot-wide, with a
group of columns X (N, n, k) built from q, v, a and the nominal model's own quantities, such that
the effect adds X @ theta [N*m] to the torque of every joint. theta is in physical units (see
``PARAMETERS``). The diagnosis selects terms; the augmented model and the identified models add
them to the nominal torque.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import id_learning.physics.friction as laws
from id_learning.errors import RobotModelError
from id_learning.physics.effects import EFFECT_NAMES, JointEffect, effect
from id_learning.physics.effects.library import LIBRARY
from id_learning.physics.nominal import NominalModel, NominalQuantities

__all__ = [
    'EFFECT_NAMES',
    'JOINT_COLUMNS',
    'LINK_SIDE_EFFECTS',
    'PARAMETERS',
    'ROBOT_WIDE',
    'EffectSpec',
    'effect_columns',
    'gravity_loaded_joints',
    'load_slope',
    'needs_derivatives',
    'needs_gravity',
    'needs_regressor',
    'uses_model_load',
    'whole_model_delay',
    'whole_model_form',
    'whole_model_scale',
    'whole_model_settings',
]


#: Parameters of each effect's columns, in column order, with units (k of them, or a prefix).
PARAMETERS: dict[str, tuple[tuple[str, str], ...]] = {
    item.name: tuple((p.name, p.unit) for p in item.parameters) for item in LIBRARY
}

ROBOT_WIDE = tuple(item.name for item in LIBRARY if item.robot_wide)
#: Effects that change the torque the links put on the joints (the load of load-dependent
#: friction), as against the drive's own terms.
LINK_SIDE_EFFECTS = tuple(item.name for item in LIBRARY if item.link_side)


@dataclass(frozen=True, eq=False)
class EffectSpec:
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
        parts += effect(self.name).label_parts(self.settings)
        return f'{self.name}[{", ".join(parts)}]' if parts else self.name

    def replace_settings(self, **changes: Any) -> EffectSpec:
        """A copy with some settings changed (a refined Stribeck velocity, payload COM)."""
        return EffectSpec(self.name, self.joint, self.joint_name, {**self.settings, **changes})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; ``from_dict`` rebuilds it."""
        return {
            'name': self.name,
            'joint': self.joint_name or None,
            'settings': dict(self.settings),
            'label': self.label,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], joints: tuple[str, ...]) -> EffectSpec:
        """Rebuild from ``to_dict`` output for a robot with these joints."""
        joint_name = data.get('joint') or ''
        if joint_name and joint_name not in joints:
            raise RobotModelError(
                f'effect {data.get("label", data["name"])} sits on joint {joint_name!r}, which '
                f'the robot {list(joints)} does not have'
            )
        joint = joints.index(joint_name) if joint_name else None
        return cls(str(data['name']), joint, joint_name, dict(data.get('settings') or {}))


JointColumns = Callable[
    [NominalQuantities, Any, Mapping[str, Any], NominalModel], tuple[np.ndarray, ...]
]

#: Effects that sit on one joint and act on it alone: their columns as functions of the nominal
#: quantities, the joint index j and the spec's settings (``JointEffect.joint_columns``).
JOINT_COLUMNS: dict[str, JointColumns] = {
    item.name: item.joint_columns for item in LIBRARY if isinstance(item, JointEffect)
}


def effect_columns(
    spec: EffectSpec, quantities: NominalQuantities, model: NominalModel
) -> np.ndarray:
    """The candidate's columns X (N, n, k): the effect adds X @ theta to each joint's tau_u [N*m].

    Raises:
        ValueError: the quantities lack what the effect needs (derivatives, regressor).
    """
    return effect(spec.name).columns(quantities, spec.joint, spec.settings, model)


def needs_derivatives(specs: list[EffectSpec]) -> bool:
    """Whether any candidate needs d tau / d q, d tau / d v or M(q).

    (A delay of the whole model's form is evaluated at the state it holds back.)
    """
    return any(effect(spec.name).needs_derivatives(spec.settings) for spec in specs)


def needs_gravity(specs: list[EffectSpec]) -> bool:
    """Whether any candidate reads the URDF's gravity torque."""
    return any(effect(spec.name).needs_gravity(spec.settings) for spec in specs)


def needs_regressor(specs: list[EffectSpec]) -> bool:
    """Whether any candidate needs the inertial-parameter regressor."""
    return any(effect(spec.name).needs_regressor for spec in specs)


def gravity_loaded_joints(
    model: NominalModel, q: np.ndarray, min_share: float = 0.05
) -> list[int]:
    """Joints whose nominal gravity torque sweeps at least ``min_share`` of their torque limit.

    These are the joints a balancer (spring, hydraulic) may sit on: heavy arms balance the
    shoulder and sometimes the elbow against gravity. ``q`` (N, n) is the recorded motion.
    """
    step = max(1, len(q) // 2000)
    gravity = model.dynamics.gravity(np.asarray(q)[::step])
    sweep = gravity.max(axis=0) - gravity.min(axis=0)
    share = sweep / model.robot.limits.torque
    return [j for j in range(model.robot.n_joints) if share[j] >= min_share]


def whole_model_settings(name: str) -> dict[str, str]:
    """Settings of a delay or torque-constant error that acts on the whole delivered torque."""
    return effect(name).whole_model_settings()


def whole_model_form(spec: EffectSpec, name: str | None = None) -> bool:
    """Whether a term acts on the whole delivered torque (``whole_model_settings``).

    A delay or torque-constant error (of effect ``name``, if given) of that form, not only on the
    URDF's torque.
    """
    return name in (None, spec.name) and effect(spec.name).is_whole_model(spec.settings)


def delay_about(spec: EffectSpec) -> float:
    """The delay [s] a signal-delay term's column is taken about; 0: its rate (first order).

    A fit sets it to its last estimate, so that a delay of several IPO cycles is fitted on the
    torque it actually shifts (``ResidualProblem``); the coefficient is the delay either way.
    """
    return effect(spec.name).linearised_about(spec.settings)


def load_slope(spec: EffectSpec, quantities: NominalQuantities) -> np.ndarray:
    """(N,) sign(L) s(v): how a load-dependent friction c |L| s(v) grows with its load.

    Per unit coefficient and N*m of link torque L (``quantities.tau_rigid``) on its joint.
    """
    j = spec.joint
    return laws.load_slope(
        quantities.v[:, j], quantities.tau_rigid[:, j], spec.settings['smoothing_velocity']
    )


def uses_model_load(spec: EffectSpec) -> bool:
    """Whether a load-dependent friction term grows with the model's link torque (its form)."""
    return effect(spec.name).uses_model_load(spec.settings)


def whole_model_scale(spec: EffectSpec) -> bool:
    """Whether a term is a label-gain error of the whole model's form (scales all delivered)."""
    item = effect(spec.name)
    return item.scales_the_label and item.is_whole_model(spec.settings)


def whole_model_delay(spec: EffectSpec) -> bool:
    """Whether a term is a label delay of the whole model's form (holds back every term)."""
    item = effect(spec.name)
    return item.delays_the_label and item.is_whole_model(spec.settings)
