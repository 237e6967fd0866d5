"""The nominal model plus identified effects: what an ``rnea_effects`` artifact holds."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import cached_property
from typing import Any

import numpy as np

from id_learning.errors import RobotModelError
from id_learning.physics.effects import JointEffect, effect
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.terms import (
    JOINT_COLUMNS,
    EffectSpec,
    effect_columns,
    needs_derivatives,
    needs_gravity,
    needs_regressor,
    whole_model_delay,
    whole_model_scale,
)
from id_learning.robot.config import RobotConfig

__all__ = ['EFFECTS_JSON', 'AugmentedModel']

#: The file a diagnosis writes its effects and its augmented model to.
EFFECTS_JSON = 'effects.json'


#: The torque (N, n) of terms evaluated apart from ``_additive``, on some quantities.
Folded = Callable[[NominalQuantities], np.ndarray]


class AugmentedModel:
    """The nominal model plus identified effects: what a ``rnea_effects`` artifact holds.

    Args:
        robot: the robot config (URDF, drives).
        target: 'motor' (tau_u, rotor inertia included) or 'joint'.
        terms: (effect, coefficients) pairs; each adds ``effect_columns(effect) @ theta``.
        nominal_joints: joints left to the nominal model (the diagnosis's per-joint fallback,
            where held-out data showed the effects do not help): their torque is the nominal one.

    Raises:
        RobotModelError: a fallback joint is not the robot's.
    """

    def __init__(
        self,
        robot: RobotConfig,
        target: str,
        terms: Sequence[tuple[EffectSpec, np.ndarray]],
        *,
        nominal_joints: Sequence[str] = (),
    ) -> None:
        """Store the terms; the URDF is read on first use."""
        self.robot = robot
        self.target = target
        self.terms = [(spec, np.asarray(theta, dtype=float)) for spec, theta in terms]
        unknown = [name for name in nominal_joints if name not in robot.joints]
        if unknown:
            raise RobotModelError(
                f'nominal_joints {unknown} are not joints of robot {robot.name} '
                f'{list(robot.joints)}'
            )
        self.nominal_joints = tuple(nominal_joints)
        self._fallback = np.array([robot.joints.index(name) for name in nominal_joints], int)

    @cached_property
    def nominal(self) -> NominalModel:
        """The nominal model the effects are added to."""
        return NominalModel(self.robot, self.target)

    def torque(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray, jerk: np.ndarray | None = None
    ) -> np.ndarray:
        """Torque (N, n) [N*m] for states (N, n); see ``augmented_torque``."""
        specs = [spec for spec, _ in self.terms]
        quantities = self.nominal.evaluate(
            np.atleast_2d(q),
            np.atleast_2d(v),
            np.atleast_2d(a),
            None if jerk is None else np.atleast_2d(jerk),
            derivatives=needs_derivatives(specs),
            regressor=needs_regressor(specs),
            gravity=needs_gravity(specs),
        )
        tau = self._additive(quantities, self.terms)
        tau[:, self._fallback] = quantities.tau_nominal[:, self._fallback]
        return tau

    def _additive(
        self,
        quantities: NominalQuantities,
        terms: Sequence[tuple[EffectSpec, np.ndarray]],
        tau: np.ndarray | None = None,
        folded: Folded | None = None,
    ) -> np.ndarray:
        """The nominal torque (or ``tau``) plus the additive terms, loads from the model.

        ``folded``: the torque of terms evaluated apart (``sample_function``), added here.
        Load-dependent friction of the model-load form (``uses_model_load``) comes after the
        others, on the link torque of the nominal model plus the link-side terms; a delay of the
        whole model's form then holds back every term but offsets; a torque-constant error of
        the whole model's form comes last, on everything else but offsets.
        """
        tau = quantities.tau_nominal.copy() if tau is None else tau
        link = quantities.tau_rigid.copy()
        offsets = np.zeros_like(tau)
        held_back = folded(quantities) if folded is not None else np.zeros_like(tau)
        tau += held_back
        deferred, scales, whole_delays = [], [], []
        for spec, theta in terms:
            item = effect(spec.name)
            if whole_model_scale(spec):
                scales.append((spec, theta))
                continue
            if item.uses_model_load(spec.settings):
                deferred.append((spec, theta))
                continue
            if whole_model_delay(spec):
                whole_delays.append(float(theta[0]))
                continue
            contribution = effect_columns(spec, quantities, self.nominal) @ theta
            tau += contribution
            if item.link_side:
                link += contribution
            if item.label_offset:
                offsets += contribution
            elif not item.delays_the_label:
                held_back += contribution
        if deferred:
            loaded = replace(quantities, tau_rigid=link)
            for spec, theta in deferred:
                contribution = effect_columns(spec, loaded, self.nominal) @ theta
                tau += contribution
                held_back += contribution
        for delay in whole_delays:
            tau += self._delayed(quantities, terms, delay, held_back, folded)
        # A torque-constant error of the whole model's form scales everything the drive
        # delivers (a current-sensor offset aside), as the diagnosis fitted it.
        delivered = tau - offsets
        for spec, theta in scales:
            tau[:, spec.joint] += float(theta[0]) * delivered[:, spec.joint]
        return tau

    def _delayed(
        self,
        quantities: NominalQuantities,
        terms: Sequence[tuple[EffectSpec, np.ndarray]],
        delay: float,
        now: np.ndarray,
        folded: Folded | None,
    ) -> np.ndarray:
        """What a delay of the whole model's form adds: the torque ``delay`` seconds back.

        The nominal torque and every other term but offsets and torque-constant errors, at
        the state ``delay`` back (positions and velocities to second order, accelerations to
        first), less their torque ``now`` (theirs, the nominal torque aside). Not the rate
        times the delay, whose d^2 / 2 tau'' error grows with the delay: the diagnosis fits
        the delay on the shifted torque (``ResidualProblem``).
        """
        others = [
            (spec, theta)
            for spec, theta in terms
            if not (effect(spec.name).delays_the_label or effect(spec.name).label_offset)
            and not whole_model_scale(spec)
        ]
        specs = [spec for spec, _ in others]
        q, v, a, jerk = quantities.q, quantities.v, quantities.a, quantities.jerk
        back = self.nominal.evaluate(
            q - delay * v + 0.5 * delay**2 * a,
            v - delay * a + 0.5 * delay**2 * jerk,
            a - delay * jerk,
            derivatives=needs_derivatives(specs),
            regressor=needs_regressor(specs),
            gravity=needs_gravity(specs),
        )
        out: np.ndarray = self._additive(back, others, None, folded) - quantities.tau_nominal - now
        return out

    def sample_function(self) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """``torque`` of one sample, q, v, a (n,) -> (n,) [N*m], for the online predictor.

        The single-joint effects (``JOINT_COLUMNS``) of one name, one column and one set of
        settings are folded: all their joints in one vectorised call with their settings as
        arrays; the rest go through ``effect_columns`` as in ``torque``. (Offsets are not
        folded beside a whole-model torque-constant error, which leaves them out.)
        """
        groups: dict[tuple[str, tuple[str, ...]], list[tuple[EffectSpec, np.ndarray]]] = {}
        rest: list[tuple[EffectSpec, np.ndarray]] = []
        scaled = any(whole_model_scale(spec) for spec, _ in self.terms)
        for spec, theta in self.terms:
            item = effect(spec.name)
            scalar = all(isinstance(x, (int, float)) for x in spec.settings.values())
            foldable = isinstance(item, JointEffect) and not (
                item.uses_model_load(spec.settings)
                or item.link_side
                or (scaled and item.label_offset)
            )
            if theta.shape == (1,) and scalar and foldable:
                key = (spec.name, tuple(sorted(spec.settings)))
                groups.setdefault(key, []).append((spec, theta))
            else:
                rest.append((spec, theta))
        folded = []
        for (name, _), members in groups.items():
            joints = np.array([spec.joint for spec, _ in members])
            keys = members[0][0].settings.keys()
            settings = {k: np.array([spec.settings[k] for spec, _ in members]) for k in keys}
            theta = np.array([theta[0] for _, theta in members])
            folded.append((JOINT_COLUMNS[name], joints, settings, theta))  # one joint effect
        specs = [spec for spec, _ in rest]
        derivatives, regressor = needs_derivatives(specs), needs_regressor(specs)
        gravity = needs_gravity(specs)
        nominal, additive, fallback = self.nominal, self._additive, self._fallback

        def folded_torque(qs: NominalQuantities) -> np.ndarray:
            out = np.zeros_like(qs.tau_nominal)
            for columns, joints, settings, theta in folded:
                np.add.at(out[0], joints, columns(qs, joints, settings, nominal)[0][0] * theta)
            return out

        def torque_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            qs = nominal.evaluate(
                q[None], v[None], a[None], derivatives=derivatives, regressor=regressor,
                gravity=gravity,
            )  # fmt: skip
            out: np.ndarray = additive(qs, rest, qs.tau_nominal.copy(), folded_torque)[0]
            out[fallback] = qs.tau_nominal[0, fallback]
            return out

        return torque_one

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; ``from_dict`` rebuilds it for the same robot."""
        return {
            'robot': self.robot.name,
            'joints': list(self.robot.joints),
            'target': self.target,
            'terms': [
                {'spec': spec.to_dict(), 'coefficients': theta.tolist()}
                for spec, theta in self.terms
            ],
            'nominal_joints': list(self.nominal_joints),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], robot: RobotConfig) -> AugmentedModel:
        """Rebuild from ``to_dict`` output (or effects.json) for ``robot``.

        Raises:
            RobotModelError: the saved joints differ from the robot's.
        """
        if list(data['joints']) != list(robot.joints):
            raise RobotModelError(
                f'the effects were identified for joints {list(data["joints"])} '
                f'({data.get("robot")}), not for {list(robot.joints)} ({robot.name})'
            )
        if 'terms' in data:
            entries = [(t['spec'], t['coefficients']) for t in data['terms']]
            fallback = data.get('nominal_joints', [])
        else:  # effects.json
            entries = [(e['model']['spec'], e['model']['coefficients']) for e in data['effects']]
            fallback = data.get('held_out_rmse_nm', {}).get('nominal_joints', [])
        terms = [
            (EffectSpec.from_dict(spec, robot.joints), np.asarray(theta, dtype=float))
            for spec, theta in entries
        ]
        return cls(robot, str(data['target']), terms, nominal_joints=list(fallback))
