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
from id_learning.physics.balancer import BALANCER_TERMS, balancer_basis
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS

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
    'needs_regressor',
    'uses_model_load',
    'whole_model_form',
    'whole_model_settings',
]


#: Parameters of each effect's columns, in column order, with units (k of them, or a prefix).
PARAMETERS: dict[str, tuple[tuple[str, str], ...]] = {
    'viscous_friction': (('coefficient', 'N*m*s/rad'),),
    'coulomb_friction': (('level', 'N*m'),),
    'stribeck_friction': (('level', 'N*m'),),
    'load_dependent_friction': (('coefficient', '1'),),
    'rotor_inertia': (('rotor_inertia_change_motor_side', 'kg*m^2'),),
    'gravity_spring': (('f0', 'N*m'), ('f1', 'N*m'), ('f2', 'N*m')),
    'payload_mass': (('mass', 'kg'), ('first_moment_x', 'kg*m'), ('first_moment_y', 'kg*m'),
                     ('first_moment_z', 'kg*m')),
    'joint_offset': (('offset', 'rad'),),
    'torque_constant_scale': (('label_gain_change', '1'),),
    'signal_delay': (('delay', 's'),),
    'cogging': (('sine', 'N*m'), ('cosine', 'N*m')),
    'torque_offset': (('offset', 'N*m'),),
    'inertial_parameter_error': (('base_parameter', 'SI'),),
}  # fmt: skip


#: The effects' stable names, in the library's order.
EFFECT_NAMES: tuple[str, ...] = tuple(PARAMETERS)

ROBOT_WIDE = ('payload_mass', 'signal_delay', 'inertial_parameter_error')
#: Effects that change the torque the links put on the joints (the load of load-dependent
#: friction), as against the drive's own terms.
LINK_SIDE_EFFECTS = ('inertial_parameter_error', 'payload_mass', 'gravity_spring', 'joint_offset')


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
        if self.name == 'stribeck_friction':
            parts.append(f'v_s={self.settings["velocity"]:g}')
        if self.name == 'viscous_friction' and self.settings.get('exponent', 1.0) != 1.0:
            linear = 'v + ' if self.settings.get('linear') else ''
            parts.append(f'{linear}|v|^{self.settings["exponent"]:g}')
        if self.name == 'cogging':
            parts.append(f'p={self.settings["periods_per_motor_turn"]}')
        if self.name == 'payload_mass':
            parts.append(str(self.settings['frame']))
            if self.settings.get('inertia'):
                parts.append('with inertia')
        if uses_model_load(self):
            parts.append('model load')
        if whole_model_form(self):
            parts.append('whole model')
        if self.name == 'gravity_spring' and 'ratio' in self.settings:
            parts.append(f'r={self.settings["ratio"]:.3g}, phi={self.settings["phase_rad"]:.3g}')
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


def _viscous(qs: NominalQuantities, j: Any, settings: Mapping[str, Any]) -> tuple[np.ndarray, ...]:
    """``friction.viscous`` of the joint's velocity, in the settings' form (exponent, linear)."""
    exponent = settings.get('exponent', 1.0)
    return laws.viscous(qs.v[:, j], exponent, linear=bool(settings.get('linear')))


def _gravity_spring(
    qs: NominalQuantities, j: Any, settings: Mapping[str, Any], model: NominalModel
) -> tuple[np.ndarray, ...]:
    """A balancer's torque columns (``physics.balancer``) for its geometry in the settings.

    Terms written before the balancer form hold a polynomial in (q - reference_rad) instead.
    """
    if 'ratio' in settings:
        basis = balancer_basis(qs.q[:, j], settings['ratio'], settings['phase_rad'])
        return tuple(basis[..., k] for k in range(BALANCER_TERMS))
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
    'viscous_friction': lambda qs, j, s, model: _viscous(qs, j, s),
    'coulomb_friction': lambda qs, j, s, model: (
        laws.coulomb(qs.v[:, j], s['smoothing_velocity']),
    ),
    'stribeck_friction': lambda qs, j, s, model: (
        laws.stribeck(qs.v[:, j], s['velocity'], s['smoothing_velocity']),
    ),
    'load_dependent_friction': lambda qs, j, s, model: (
        laws.load_dependent(qs.v[:, j], qs.tau_rigid[:, j], s['smoothing_velocity']),
    ),
    'rotor_inertia': lambda qs, j, s, model: (model.robot.drives.gear_ratio[j] ** 2 * qs.a[:, j],),
    'gravity_spring': _gravity_spring,
    'torque_constant_scale': lambda qs, j, s, model: (qs.tau_nominal[:, j],),
    'cogging': _cogging,
    'torque_offset': lambda qs, j, s, model: (np.ones_like(qs.q[:, j]),),
}


def effect_columns(
    spec: EffectSpec, quantities: NominalQuantities, model: NominalModel
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
        if j is None:
            raise ValueError('joint_offset needs a joint')
        if qs.dtau_dq is None:
            raise ValueError('joint_offset needs quantities evaluated with derivatives=True')
        return qs.dtau_dq[:, :, j : j + 1].copy()
    if name == 'signal_delay':
        # Currents at t belong to the motion at t - d: tau(t - d) ~ tau(t) - d dtau/dt. The
        # diagnosis' 'whole model' form adds the other effects' rate along the recording
        # (``ResidualProblem``); on single states only the nominal torque's rate is known.
        return -model.nominal_rate(qs)[:, :, None]
    if name == 'payload_mass':
        if qs.regressor is None:
            raise ValueError('payload_mass needs quantities evaluated with regressor=True')
        body, mapping = model.payload_map(
            str(settings['frame']), settings['com_guess_m'], bool(settings.get('inertia'))
        )
        block = qs.regressor[
            :, :, N_INERTIAL_PARAMETERS * body : N_INERTIAL_PARAMETERS * (body + 1)
        ]
        return block @ mapping
    if name == 'inertial_parameter_error':
        if qs.regressor is None:
            raise ValueError('inertial_parameter_error needs quantities with regressor=True')
        return qs.regressor @ np.asarray(settings['base_directions'])
    raise ValueError(f'unknown effect {name!r}')


def needs_derivatives(specs: list[EffectSpec]) -> bool:
    """Whether any candidate needs d tau / d q, d tau / d v or M(q).

    (A delay of the whole model's form is evaluated at the state it holds back.)
    """
    return any(
        spec.name == 'joint_offset' or (spec.name == 'signal_delay' and not whole_model_form(spec))
        for spec in specs
    )


def needs_regressor(specs: list[EffectSpec]) -> bool:
    """Whether any candidate needs the inertial-parameter regressor."""
    return any(spec.name in ('payload_mass', 'inertial_parameter_error') for spec in specs)


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


#: The setting that puts a delay or a torque-constant error in the whole model's form.
_WHOLE_MODEL_KEY = {'signal_delay': 'rate_of', 'torque_constant_scale': 'of'}


def whole_model_settings(name: str) -> dict[str, str]:
    """Settings of a delay or torque-constant error that acts on the whole delivered torque."""
    return {_WHOLE_MODEL_KEY[name]: 'model'}


def whole_model_form(spec: EffectSpec, name: str | None = None) -> bool:
    """Whether a term acts on the whole delivered torque (``whole_model_settings``).

    A delay or torque-constant error (of effect ``name``, if given) of that form, not only on the
    URDF's torque.
    """
    key = _WHOLE_MODEL_KEY.get(spec.name)
    return key is not None and name in (None, spec.name) and spec.settings.get(key) == 'model'


def delay_about(spec: EffectSpec) -> float:
    """The delay [s] a signal-delay term's column is taken about; 0: its rate (first order).

    A fit sets it to its last estimate, so that a delay of several IPO cycles is fitted on the
    torque it actually shifts (``ResidualProblem``); the coefficient is the delay either way.
    """
    return float(spec.settings.get('about', 0.0)) if spec.name == 'signal_delay' else 0.0


def load_slope(spec: EffectSpec, quantities: NominalQuantities) -> np.ndarray:
    """(N,) sign(L) s(v): how a load-dependent friction c |L| s(v) grows with its load.

    Per unit coefficient and N*m of link torque L (``quantities.tau_rigid``) on its joint.
    """
    j = spec.joint
    return laws.load_slope(
        quantities.v[:, j], quantities.tau_rigid[:, j], spec.settings['smoothing_velocity']
    )


def uses_model_load(spec: EffectSpec) -> bool:
    """Whether a load-dependent friction term grows with the model's link torque (its form).

    The load is the link torque of the whole model (nominal plus the link-side effects): with a
    payload or a balancer the URDF's alone is far off. Terms written before this form (no
    'load' setting) take the URDF's rigid-body torque.
    """
    return spec.name == 'load_dependent_friction' and spec.settings.get('load') == 'model'
