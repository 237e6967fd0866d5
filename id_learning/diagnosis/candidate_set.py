"""The library's candidates on one problem, and the tuning of a selected effect's settings.

Columns, testability, plausibility and priors of every candidate; the nonlinear settings of a
selected effect (Stribeck velocity, payload centre of mass, balancer geometry, the load of
load-dependent friction) tuned on the training part.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from typing import Any, cast

import numpy as np

from id_learning.diagnosis.aliases import AliasSet, holds_columns
from id_learning.diagnosis.candidates import (
    ExcitationFacts,
    PlausibilityFacts,
    plausibility,
    testability,
)
from id_learning.diagnosis.design import Design, Fit
from id_learning.diagnosis.friction_shape import (
    SHAPE_EVIDENCE,
    FrictionShape,
    identify_friction_shape,
    reshaped,
)
from id_learning.diagnosis.problem import ResidualProblem
from id_learning.diagnosis.refinement import choose_form, refine_setting
from id_learning.physics.effects import REGISTRY, effect
from id_learning.physics.terms import EffectSpec, whole_model_settings

__all__ = ['CandidateSet']

#: Most refits of model-load friction and the link-side terms that load it, and the relative
#: change of every coefficient at which they have settled (``load_on_model``).
LOAD_ITERATIONS = 5
LOAD_TOLERANCE = 0.01

#: Step in a log setting for the columns' derivative (``setting_sensitivities``).
_LOG_STEP = 0.05

#: The effects that special ones are cases of (``Effect.special_case_of``).
_GENERAL_EFFECTS = frozenset(item.special_case_of for item in REGISTRY.values()) - {None}


class CandidateSet:
    """The library's columns on every part, their testability and plausibility rules."""

    def __init__(self, problem: ResidualProblem) -> None:
        self.problem = problem
        model = problem.model
        self.specs = {spec.label: spec for spec in problem.library}
        self.columns: dict[str, dict[str, np.ndarray]] = {}
        self.raw: dict[str, np.ndarray] = {}
        retention: dict[str, float] = {}
        norm: dict[str, np.ndarray] = {}
        for label, spec in self.specs.items():
            self.columns[label], self.raw[label], retention[label] = problem.columns(spec)
            train = self.columns[label]['train']
            weighted = train * problem.weights[None, :, None]
            norm[label] = np.sqrt(np.sum(weighted * train, axis=(0, 1)))
        facts = ExcitationFacts(problem.part('v', 'train'), problem.cutoff, norm, retention)
        self.verdicts = {
            label: testability(spec, facts, model, problem.config)
            for label, spec in self.specs.items()
        }
        self.testable = [label for label in self.specs if self.verdicts[label][0]]
        #: per joint, the friction curve's (v_eps, viscous exponent) (``friction_shape``).
        self.friction_shapes = self._shape_friction()
        quantities = problem.joined_quantities()
        self.facts = PlausibilityFacts(
            rigid_rms=np.sqrt(np.mean(quantities.tau_rigid**2, axis=0)),
            gravity=model.dynamics.gravity(quantities.q),
            moving_mass_kg=model.dynamics.total_moving_mass(),
            body_parameters=model.dynamics.inertial_parameters().reshape(-1, 10),
            positions=np.stack([quantities.q.min(axis=0), quantities.q.max(axis=0)]),
        )

    def _shape_friction(self) -> list[FrictionShape]:
        """Identify each joint's friction curve shape and put it in its friction candidates."""
        problem = self.problem
        default = (problem.config.smoothing_velocity, 1.0)
        if not any(effect(name).friction_shaped for name in problem.config.effects):
            return [default] * problem.robot.n_joints
        y = problem.residual('train')
        n_eff = problem.n_effective('train')
        shapes = []
        for j, joint in enumerate(problem.robot.joints):
            others = self._others_on(j)

            def columns_of(spec: EffectSpec, j: int = j) -> np.ndarray:
                return problem.columns(spec)[0]['train'][:, j, :]

            shape = identify_friction_shape(
                j, joint, y[:, j], others=others, columns_of=columns_of,
                effective_samples=float(n_eff[j]), config=problem.config,
            )  # fmt: skip
            shapes.append(shape)
            if shape != default:
                self._reshape(j, shape, list(self.specs))
        return shapes

    def _reshape(self, j: int, shape: FrictionShape, labels: Sequence[str]) -> dict[str, str]:
        """Give joint j's friction candidates among ``labels`` a curve shape; old -> new labels."""
        renamed = {}
        for label in labels:
            if _shaped_on(self.specs[label], j):
                new = reshaped(self.specs[label], shape)
                self._swap(label, new)
                renamed[label] = new.label
        return renamed

    def _others_on(self, j: int) -> list[np.ndarray]:
        """Training columns (M, k) on joint j of every testable candidate but its friction laws.

        Of an effect's exclusive variants (a spring's forms) only the first: together they
        would span more than any one form can.
        """
        out, seen = [], set()
        for label in self.testable:
            spec = self.specs[label]
            if effect(spec.name).exclusive_variants:
                if (spec.name, spec.joint) in seen:
                    continue
                seen.add((spec.name, spec.joint))
            column = self.columns[label]['train'][:, j, :]
            if not _shaped_on(spec, j) and np.any(column):
                out.append(column)
        return out

    def design(
        self,
        y: dict[str, np.ndarray],
        n_eff: dict[str, np.ndarray],
        extra: dict[str, dict[str, np.ndarray]] | None = None,
    ) -> Design:
        """The regression problem over the testable candidates (and ``extra`` columns).

        The link parameters' changes (inertial_parameter_error) carry the CAD prior of
        ``physics.base_parameters``: a URDF's masses and centres of mass are good to ten per
        cent and a few centimetres, so the data move them only as far as they show.
        """
        columns = {label: self.columns[label] for label in self.testable} | (extra or {})
        return self.design_over(y, columns, n_eff)

    def design_over(
        self,
        y: dict[str, np.ndarray],
        columns: dict[str, dict[str, np.ndarray]],
        n_eff: dict[str, np.ndarray],
    ) -> Design:
        """The regression over some columns, each candidate among them under its prior.

        Every fit here holds the priors, a setting's refinement too: there the link parameters
        free of their CAD prior took a payload's mass at will, and its centre of mass, refitted,
        ran out to a metre.
        """
        return self.problem.design(y, columns, n_eff, self._priors(columns))

    def _priors(self, labels: Iterable[str]) -> dict[str, np.ndarray]:
        """Prior precisions of the candidates among ``labels`` that carry one."""
        out = {}
        for label in labels:
            spec = self.specs.get(label)
            if spec is None:
                continue
            precision = effect(spec.name).prior_precision(
                spec.joint, spec.settings, self.problem.model, as_datasheet=False
            )
            if precision is not None:
                out[label] = precision
        return out

    def setting_sensitivities(self, design: Design, fit: Fit) -> dict[str, dict[str, np.ndarray]]:
        """Columns of the change of a fit's torque with each hump's tuned velocity (log v_s).

        A Stribeck level is fitted at its velocity as refined (or picked) on the same data, and
        the two trade (the hump's area): taken as exact, the velocity leaves the level's
        interval too narrow. Free beside the fit (the linearised velocity), these columns widen
        it by what the velocity leaves unknown. Keyed ``<label>:log_velocity``.
        """
        out = {}
        for label in fit.groups:
            spec = self.specs[label]
            item = effect(spec.name)
            if not item.hump:
                continue
            (axis,) = item.tuned_settings(spec.settings)
            level = design.physical(fit, label)
            velocity = float(spec.settings[axis.name])
            up, down = (
                self.problem.columns(
                    spec.replace_settings(**{axis.name: velocity * math.exp(step)})
                )[0]
                for step in (_LOG_STEP, -_LOG_STEP)
            )
            out[log_velocity_of(label)] = {
                part: (up[part] - down[part]) @ level[:, None] / (2 * _LOG_STEP) for part in up
            }
        return out

    def datasheet_unknowns(
        self, selected: Sequence[str]
    ) -> tuple[list[str], dict[str, np.ndarray]]:
        """The candidates for datasheet values no selected effect names, and their priors.

        Every joint's torque constant is known to its tolerance, every rotor inertia leaves out
        brake and gear input stage, the link parameters are CAD's. Fixed at those values they
        set a scale that every parameter in torque units shares: with one joint's torque
        constant 4 % off and not named, every named scale, friction level and payload mass came
        out about 4 % off, with intervals a tenth as wide. Estimated free within their
        tolerances (marginalised), they widen the intervals by what they leave unknown.
        """
        model = self.problem.model
        named = {(self.specs[g].name, self.specs[g].joint) for g in selected}
        labels, priors = [], {}
        for label in self.testable:
            spec = self.specs[label]
            item = effect(spec.name)
            if not item.datasheet_value or (spec.name, spec.joint) in named:
                continue
            if item.motor_side_only and model.target != 'motor':
                continue  # a joint torque sensor's label holds none
            precision = item.prior_precision(spec.joint, spec.settings, model, as_datasheet=True)
            if precision is None:
                continue  # no datasheet value to hold it near
            priors[label] = precision
            labels.append(label)
        return labels, priors

    def plausible(self, design: Design, fit: Fit) -> dict[str, tuple[bool, str]]:
        """The plausibility rule's verdict on every group of a fit."""
        out = {}
        for group in fit.groups:
            theta = design.physical(fit, group)
            out[group] = plausibility(
                self.specs[group],
                theta,
                self.raw[group],
                self.problem.model,
                self.facts,
                # Estimation noise, not the misfit of effects still missing, widens the margin.
                covariance=design.physical_covariance(fit, group, noise_only=True),
            )
        return out

    def variants(self, a: str, b: str) -> bool:
        """Whether two candidates are variants of one effect on one joint."""
        return (
            self.specs[a].name == self.specs[b].name and self.specs[a].joint == self.specs[b].joint
        )

    def swappable(self, a: str, b: str) -> bool:
        """Whether two candidates of different effects act on one joint (``find_aliases``)."""
        sa, sb = self.specs[a], self.specs[b]
        return sa.joint is not None and sa.joint == sb.joint and sa.name != sb.name

    def is_general(self, label: str) -> bool:
        """Whether a candidate is a general effect that special ones are cases of."""
        return self.specs[label].name in _GENERAL_EFFECTS

    def conflicts(self, label: str, selected: Sequence[str]) -> bool:
        """Two Stribeck velocities of one joint never enter together."""
        if not effect(self.specs[label].name).exclusive_variants:
            return False
        return any(self.variants(label, other) for other in selected)

    def refine(
        self, selected: Sequence[str], y: dict[str, np.ndarray], n_eff: dict[str, np.ndarray]
    ) -> list[str]:
        """Tune the selected effects' nonlinear settings; the selection's new labels.

        Stribeck velocity, payload COM and balancer geometry, then the friction's load. An
        effect with forms (exclusive variants) takes the one that, refined, predicts the
        held-out part best.
        """
        selected = list(selected)
        for index, label in enumerate(list(selected)):
            spec = self.specs[label]
            if self._judged_beside_fixed_humps(spec):
                selected = self._refine_hump(selected, index, y, n_eff)
                continue
            item = effect(spec.name)
            if item.exclusive_variants and not item.hump:
                selected[index] = self._choose_form(selected, index, y, n_eff)
                continue
            if not (item.tuned_settings(spec.settings) or item.fit_sets_settings):
                continue
            others = {g: self.columns[g] for g in selected if g != label}
            design_of = functools.partial(self.design_over, y, n_eff=n_eff)
            refined = refine_setting(self.problem, others, spec, design_of)
            if refined is None:
                continue
            self._swap(label, refined)
            selected[index] = refined.label
        return self.load_on_model(selected, y, n_eff)

    def _choose_form(
        self,
        selected: list[str],
        index: int,
        y: dict[str, np.ndarray],
        n_eff: dict[str, np.ndarray],
    ) -> str:
        """A selected effect in its form that predicts held-out best (``choose_form``)."""
        label = selected[index]
        others = {g: self.columns[g] for g in selected if g != label}
        forms = [self.specs[t] for t in self.testable if t == label or self.variants(label, t)]
        design_of = functools.partial(self.design_over, y, n_eff=n_eff)
        best = choose_form(self.problem, others, forms, design_of)
        if best.label in self.specs and best.label != label:
            self._swap(best.label, best)  # another form: the selected one stays a candidate
        elif best is not self.specs[label]:
            self._swap(label, best)
        return best.label

    def forms_of(self, label: str) -> list[str]:
        """A selected effect's other testable forms with as many coefficients (no hump's)."""
        item = effect(self.specs[label].name)
        if not item.exclusive_variants or item.hump:
            return []
        size = self.columns[label]['train'].shape[2]
        return [t for t in self._variants_of(label) if self.columns[t]['train'].shape[2] == size]

    def _variants_of(self, label: str) -> list[str]:
        return [t for t in self.testable if t != label and self.variants(label, t)]

    def _judged_beside_fixed_humps(self, spec: EffectSpec) -> bool:
        """Whether a Stribeck hump's joint was given a softer turn or a curved viscous law."""
        if not effect(spec.name).hump or spec.joint is None:
            return False
        eps, exponent = self.friction_shapes[spec.joint]
        return eps > self.problem.config.smoothing_velocity or exponent != 1.0

    def _refine_hump(
        self,
        selected: list[str],
        index: int,
        y: dict[str, np.ndarray],
        n_eff: dict[str, np.ndarray],
    ) -> list[str]:
        """Tune a Stribeck velocity and judge its joint's softer turn and curved law again.

        The friction shape is judged beside humps at fixed velocities. A softer turn through
        zero speed takes away torque that a hump puts back, so a hump at another velocity is
        partly made up by a softer turn, and the refined hump grows to match (193 N*m for 70 on
        joint 1 of twin seeds 10 and 15, every effect on). A thinning viscous law, steep at
        low speed, makes one up too: on seed 15 at 600 s joint 3's |v|^0.8 took a 30 mrad/s
        hump's place, the hump went to 51 mrad/s and the Coulomb level read 93 N*m for 120.
        Here each combination of the configured and the judged smoothing and law gets its best
        hump velocity, and each departure from the configured shape must again earn the shape
        step's evidence. A sharper turn than configured is not judged again: the humps beside
        it in the shape step already put torque back at low speed, as it does. The new labels.
        """
        label = selected[index]
        spec = self.specs[label]
        j = cast(int, spec.joint)  # a joint's hump (_judged_beside_fixed_humps)
        current = self.friction_shapes[j]
        default = self.problem.config.smoothing_velocity
        rest = [g for g in selected if g != label]
        trials: dict[FrictionShape, tuple[float, EffectSpec]] = {}
        eps_tried = sorted({default, current[0]}) if current[0] > default else [current[0]]
        for shape in [(e, d) for e in eps_tried for d in sorted({1.0, current[1]})]:
            specs = {
                g: reshaped(self.specs[g], shape)
                if _shaped_on(self.specs[g], j)
                else self.specs[g]
                for g in rest
            }
            others = {
                s.label: self.columns[g] if s.label == g else self.problem.columns(s)[0]
                for g, s in specs.items()
            }
            hump = reshaped(spec, shape)
            design_of = functools.partial(self.design_over, y, n_eff=n_eff)
            hump = refine_setting(self.problem, others, hump, design_of) or hump
            design = design_of({**others, hump.label: self.problem.columns(hump)[0]})
            residual = design.residual(design.fit([*others, hump.label]), 'train')[:, j]
            trials[shape] = (float(self.problem.weights[j] * residual @ residual), hump)
        scale = max(min(t[0] for t in trials.values()), 1e-300) / float(n_eff['train'][j])

        def score(shape: FrictionShape) -> float:
            changed = (shape[0] != default) + (shape[1] != 1.0)
            return trials[shape][0] / scale + SHAPE_EVIDENCE * changed

        shape = min(trials, key=score)
        hump = trials[shape][1]
        renamed = {}
        if shape != current:
            self.friction_shapes[j] = shape
            renamed = self._reshape(j, shape, list(self.testable))
        if hump.label != renamed.get(label, label):
            self._swap(renamed.get(label, label), hump)
        return [hump.label if g == label else renamed.get(g, g) for g in selected]

    def whole_model(
        self, selected: list[str], y: dict[str, np.ndarray], n_eff: dict[str, np.ndarray]
    ) -> bool:
        """Give delays and torque-constant errors the whole model's torque; whether new forms.

        A drive delivers the whole torque late, and a wrong torque constant scales all of it,
        friction, payload and balancer included, not only the URDF's: with the rigid body's
        torque alone a delay soaks up a share of friction (a viscous term's rate is an inertia)
        and a torque-constant error trades with the payload. The other selected effects, at
        their fitted values, enter every delay and torque-constant candidate's column (a torque
        offset, which sits in the current sensor, is not scaled). True when candidates took the
        whole model's form (the selection then runs again, and this once more, so that the
        columns hold the final effects).
        """
        others = [g for g in selected if not _whole_model_kind(self.specs[g])]
        if not others or not self._whole_model_candidates():
            return False
        design = self.design(y, n_eff)
        return self.hold_torque_of(design, design.fit(selected))

    def hold_torque_of(self, design: Design, fit: Fit) -> bool:
        """Put a fit's torque in the delay and torque-constant columns; whether new forms.

        Every group of the fit but the delays and torque constants enters at its fitted value
        (``whole_model``); the delay's column is taken about its fitted delay, if it is in the
        fit. A delay's value depends on the torque its column holds (it is fitted on that
        torque's rate), so a fit that reports it (``IntervalRule``) holds its own torque.
        """
        others = [g for g in fit.groups if not _whole_model_kind(self.specs[g])]
        terms = [(self.specs[g], design.physical(fit, g)) for g in others]
        self.problem.rate_terms = terms
        self.problem.scale_terms = [t for t in terms if not effect(t[0].name).label_offset]
        changed = False
        for label in self._whole_model_candidates():
            spec = self.specs[label]
            whole = spec.replace_settings(**whole_model_settings(spec.name))
            if effect(spec.name).delays_the_label and label in fit.groups:
                # Its column about the delay just fitted (``delay_about``).
                delay = float(design.physical(fit, label)[0])
                whole = whole.replace_settings(about=max(delay, 0.0))
            self._swap(label, whole)
            changed |= whole.label != label
        return changed

    def _whole_model_candidates(self) -> list[str]:
        """The testable delay and torque-constant candidates."""
        return [g for g in self.testable if _whole_model_kind(self.specs[g])]

    def saved(self) -> tuple[Any, ...]:
        """What ``refine`` changes: specs, columns, the problem's terms (see ``restore``)."""
        problem = self.problem
        return (
            dict(self.specs), dict(self.columns), dict(self.raw), dict(self.verdicts),
            list(self.testable), problem.link_terms, problem.load_terms, problem.rate_terms,
            problem.scale_terms,
        )  # fmt: skip

    def restore(self, saved: tuple[Any, ...]) -> None:
        """Go back to a ``saved`` state."""
        problem = self.problem
        (self.specs, self.columns, self.raw, self.verdicts, self.testable,
         problem.link_terms, problem.load_terms, problem.rate_terms,
         problem.scale_terms) = saved  # fmt: skip

    def _swap(self, label: str, refined: EffectSpec) -> None:
        """Put a refined spec (and its columns) in the place of a candidate."""
        new = refined.label
        self.specs[new] = refined
        self.columns[new], self.raw[new], _ = self.problem.columns(refined)
        self.verdicts.setdefault(new, self.verdicts[label])
        self.testable = [new if t == label else t for t in self.testable if t != new or t == label]

    def load_on_model(
        self, selected: list[str], y: dict[str, np.ndarray], n_eff: dict[str, np.ndarray]
    ) -> list[str]:
        """Let selected load-dependent friction see the model's link torque, not the URDF's.

        A payload, a balancer or changed link parameters change the torque the gears carry;
        with the URDF's alone the friction coefficient soaks up their share (``uses_model_load``).
        The friction and the link-side terms that load it are fitted together, linearised about
        the last fit (``ResidualProblem.load_offset``) until the fit stops moving.
        """
        specs = [self.specs[label] for label in selected]
        loads = [
            i for i, s in enumerate(specs)
            if effect(s.name).model_load_settings(s.settings) is not None
        ]  # fmt: skip
        link = [g for g, s in zip(selected, specs, strict=True) if effect(s.name).link_side]
        problem, selected = self.problem, list(selected)
        if not loads or not link:
            if problem.load_terms:  # a friction no longer selected loads no link column
                problem.load_terms = []
                self._refresh_link_side()
            return selected
        previous = np.full(len(loads), np.inf)
        for _ in range(LOAD_ITERATIONS):
            design = self.design(y, n_eff)
            fit = design.fit(selected)
            problem.link_terms = [(self.specs[g], design.physical(fit, g)) for g in link]
            terms = []
            for i in loads:
                spec = self.specs[selected[i]]
                settings = effect(spec.name).model_load_settings(spec.settings)
                assert settings is not None  # only such frictions are in ``loads``
                refined = spec.replace_settings(**settings)
                terms.append((refined, design.physical(fit, selected[i])))
                self._swap(selected[i], refined)
                selected[i] = refined.label
            problem.load_terms = terms
            self._refresh_link_side()
            now = np.concatenate([theta for _, theta in terms])
            if np.all(abs(now - previous) <= LOAD_TOLERANCE * abs(now)):
                break
            previous = now
        return selected

    def _refresh_link_side(self) -> None:
        """Rebuild the link-side candidates' columns (they carry the friction's share)."""
        for label in self.testable:
            if effect(self.specs[label].name).link_side:
                self._swap(label, self.specs[label])

    def _general_of(self, special: str, general: str) -> bool:
        """Declared so, or its columns hold the special one's (a torsion spring's constant)."""
        if effect(self.specs[special].name).special_case_of == self.specs[general].name:
            return True
        return holds_columns(self.columns[general]['train'], self.columns[special]['train'])

    def special_cases(self, selected: Sequence[str], aliases: Sequence[AliasSet]) -> list[str]:
        """``selected`` with each general effect replaced by a special case that mimics it.

        Of several, the one that leaves least of the general effect's contribution. Likewise a
        gravity spring that an offset or a link-parameter error mimics gives way to it: the data
        cannot tell them apart, and a spring claims hardware the robot may not have.
        """
        out = list(selected)
        for alias in aliases:
            special = [m for m in alias.members[1:] if self._general_of(m, alias.representative)]
            if effect(self.specs[alias.representative].name).claims_hardware:
                special = [
                    m
                    for m in alias.members[1:]
                    if effect(self.specs[m].name).stands_in_for_hardware
                ]
            if special:
                best = min(special, key=lambda m: alias.unexplained.get(m, math.inf))
                out[out.index(alias.representative)] = best
        return out

    def without_generalisations(self, aliases: Sequence[AliasSet]) -> list[AliasSet]:
        """Alias sets without the general effects of their (special-case) representatives."""
        out = []
        for alias in aliases:
            members = [m for m in alias.members if not self._general_of(alias.representative, m)]
            if len(members) > 1:
                keep = set(members)
                out.append(
                    AliasSet(
                        alias.representative,
                        members,
                        {k: v for k, v in alias.canonical_correlation.items() if k in keep},
                        {k: v for k, v in alias.unexplained.items() if k in keep},
                    )
                )
        return out

    def untestable_summary(self) -> list[dict[str, Any]]:
        """Untestable candidates grouped by effect and joint, with the reason."""
        groups: dict[tuple[str, str], list[str]] = {}
        for label, spec in self.specs.items():
            groups.setdefault((spec.name, spec.joint_name), []).append(label)
        out = []
        for (name, joint), labels in groups.items():
            bad = [label for label in labels if not self.verdicts.get(label, (True, ''))[0]]
            if not bad:
                continue
            out.append(
                {
                    'name': name,
                    'joint': joint or None,
                    'all_variants': len(bad) == len(labels),
                    'variants': {label: self.verdicts[label][1] for label in bad},
                    'reason': self.verdicts[bad[0]][1],
                }
            )
        return out


def log_velocity_of(label: str) -> str:
    """A Stribeck candidate's linearised log-velocity column (``setting_sensitivities``)."""
    return f'{label}:log_velocity'


def _shaped_on(spec: EffectSpec, j: int) -> bool:
    """Whether a candidate is one of joint j's friction laws (they share its curve shape)."""
    return spec.joint == j and effect(spec.name).friction_shaped


def _whole_model_kind(spec: EffectSpec) -> bool:
    """Whether a candidate's columns hold the other effects' torque in the whole model's form."""
    return effect(spec.name).whole_model_key is not None
