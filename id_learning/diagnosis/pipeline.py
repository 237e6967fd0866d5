"""Diagnose a recording: where the nominal model and the measurements disagree, and why.

1. Nominal model: URDF RNEA plus the datasheet rotor inertia, on a controller's inputs (the
   recorded motion, ``dataset.inputs``); residual r = filtered label minus the nominal torque
   filtered exactly like the label.
2. Candidates: every named effect on every joint (``candidates``), its columns filtered exactly
   like the label, edges trimmed where the zero-phase filter starts up. With the study's
   preprocessing (``PreprocessConfig.mode='study'``) the columns are built on the filtered
   motion and meet the filtered label unfiltered, as the study's instantaneous models do.
3. Noise: the filtered label's noise level and correlation time from the raw label's
   high-frequency floor and the filter (``statistics``); rows are weighted by them.
4. Selection: forward group selection with F test, BIC, held-out gain and plausibility; alias sets;
   untestable effects; the unexplained remainder (``selection``).
5. Refit with the selected effects, held-out RMSE before/after each (waterfall), variance
   explained, parameters with confidence intervals for the effective sample size.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy import optimize, signal, stats

from id_learning.dataset.preprocess import Dataset, prepare_dataset
from id_learning.dataset.recording import Recording
from id_learning.dataset.signals import butterworth, differentiate
from id_learning.dataset.statistics import (
    NoiseEstimate,
    estimate_noise,
    integrated_autocorrelation,
)
from id_learning.diagnosis.candidates import (
    SPECIAL_CASES,
    ExcitationFacts,
    PlausibilityFacts,
    build_library,
    describe_parameters,
    plausibility,
    testability,
)
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.locate import JointLocation, locate_residual
from id_learning.diagnosis.selection import (
    PARTS,
    AliasSet,
    Design,
    Fit,
    SelectionResult,
    find_aliases,
    forward_select,
    noise_consistency,
)
from id_learning.errors import DatasetError
from id_learning.physics.augmented import AugmentedModel
from id_learning.physics.balancer import BALANCER_PHASES, BALANCER_RATIOS
from id_learning.physics.base_parameters import CadPrior
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.terms import (
    LINK_SIDE_EFFECTS,
    EffectSpec,
    effect_columns,
    needs_derivatives,
    needs_regressor,
    uses_model_load,
)
from id_learning.robot.config import RobotConfig

__all__ = [
    'DiagnosisResult',
    'FoundEffect',
    'Remainder',
    'augmented_torque',
    'column_motion',
    'evaluation_rows',
    'filtered_prediction',
    'run_diagnosis',
]

_LOG = logging.getLogger(__name__)
SCHEMA = 'id_learning.diagnosis/1'
#: Prior std of a label gain (torque-constant error) around 0, as in the identification.
LABEL_GAIN_STD = 0.05
#: Effects whose signature switches with the sign of v or the position within a motor turn: the
#: low-pass can remove most of it, so their testability checks what the filter keeps.
SWITCHING_EFFECTS = ('coulomb_friction', 'stribeck_friction', 'load_dependent_friction', 'cogging')


# -- result types ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class FoundEffect:
    """One effect the refit model contains.

    Attributes:
        spec: the candidate (name, joint, column settings).
        status: 'found' (named) or 'alias' (kept in the model, but one of an alias set).
        confidence: 'high', or 'low' when a structured remainder on its joints is larger than
            what it explains there.
        coefficients: (k,) column coefficients in physical units (the model's parameters).
        coefficients_ci: (k, 2) 95 % confidence intervals of the coefficients.
        parameters: physical parameters with intervals (``describe_parameters``).
        contribution_rms_nm: (n,) RMS of the filtered torque it adds per joint [N*m].
        variance_explained: (n,) share of the nominal residual's held-out variance it removed.
        variance_explained_total: the same over all joints, noise-weighted.
        selection: the tests when it entered (F, p-value, delta BIC, held-out gain).
    """

    spec: EffectSpec
    status: str
    confidence: str
    coefficients: np.ndarray
    coefficients_ci: np.ndarray
    parameters: list[dict[str, Any]]
    contribution_rms_nm: np.ndarray
    variance_explained: np.ndarray
    variance_explained_total: float
    selection: dict[str, float]

    @property
    def name(self) -> str:
        """The effect's stable name."""
        return self.spec.name

    @property
    def label(self) -> str:
        """name[joint, ...]."""
        return self.spec.label


@dataclass(frozen=True)
class Remainder:
    """What is left on one joint after the refit (both parts).

    Attributes:
        joint: joint name.
        rms_nm: residual RMS [N*m].
        noise_nm: estimated noise level of the filtered label [N*m].
        ratio: rms_nm / noise_nm.
        p_value: chi^2 variance test against the noise level, effective samples.
        correlation_ratio: residual correlation time / the filtered noise's (1 for noise).
        structured: a remainder no candidate explains: larger than the noise level (variance
            test and ``noise_tolerance``), or above it and correlated for much longer than
            filtered noise (``structure_correlation_ratio``).
    """

    joint: str
    rms_nm: float
    noise_nm: float
    ratio: float
    p_value: float
    correlation_ratio: float
    structured: bool


@dataclass(frozen=True, eq=False)
class DiagnosisResult:
    """Everything a diagnosis found; ``to_json`` gives effects.json.

    Attributes:
        robot: the robot config (not serialised; needed to evaluate the augmented model).
        target: 'motor' or 'joint'.
        sources: recordings diagnosed.
        duration_s: total recorded time [s].
        noise: the label's noise estimate.
        effective_samples: {'train', 'test'} -> (n,) independent samples per joint.
        effects: effects in the refit model, in the order they entered.
        alias_sets: effects this excitation cannot tell apart.
        untestable: candidates the excitation cannot show, with reasons.
        remainder: per joint, what is left.
        rmse_before_nm, rmse_after_nm: (n,) held-out RMSE of the nominal and the refit model.
        waterfall: per added effect, (label, (n,) held-out RMSE after adding it [N*m]).
        location: per joint, where the nominal residual lives.
        stop_reason: why the selection stopped.
        rejected: the best candidate that did not enter, and why.
        config: the settings used (JSON-ready).
        settings: the diagnosis config (not serialised; ``config`` is its JSON form).
        series: on the kept rows of both parts (not serialised): 'time_s' (M,), 'is_test' (M,),
            'label' (filtered label), 'residual_before' (label minus nominal) and
            'residual_after' (label minus refit model), each (M, n) [N*m].
    """

    robot: RobotConfig
    target: str
    sources: list[str]
    duration_s: float
    noise: NoiseEstimate
    effective_samples: dict[str, np.ndarray]
    effects: list[FoundEffect]
    alias_sets: list[AliasSet]
    untestable: list[dict[str, Any]]
    remainder: list[Remainder]
    rmse_before_nm: np.ndarray
    rmse_after_nm: np.ndarray
    waterfall: list[tuple[str, np.ndarray]]
    location: list[JointLocation]
    stop_reason: str
    rejected: dict[str, Any] | None
    config: dict[str, Any] = field(default_factory=dict)
    series: dict[str, np.ndarray] = field(default_factory=dict)
    settings: DiagnosisConfig | None = None

    @property
    def joints(self) -> tuple[str, ...]:
        """Joint names, the column order of every array."""
        return self.robot.joints

    def named_effects(self) -> list[FoundEffect]:
        """Effects named without ambiguity (not part of an alias set)."""
        return [effect for effect in self.effects if effect.status == 'found']

    def untestable_effects(self) -> list[tuple[str, str | None]]:
        """(name, joint) pairs none of whose candidates this excitation can show."""
        return [(e['name'], e['joint']) for e in self.untestable if e['all_variants']]

    def structured_joints(self) -> list[str]:
        """Joints with an unexplained, structured remainder."""
        return [r.joint for r in self.remainder if r.structured]

    @cached_property
    def augmented_model(self) -> AugmentedModel:
        """The refit model: nominal plus every effect (aliases' representatives included)."""
        return AugmentedModel(
            self.robot, self.target, [(e.spec, e.coefficients) for e in self.effects]
        )

    @property
    def nominal_model(self) -> NominalModel:
        """The nominal model the effects are added to (built on first use)."""
        return self.augmented_model.nominal

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (effects.json)."""
        joints = list(self.joints)

        def member(label: str) -> dict[str, Any]:
            for effect in self.effects:
                if effect.label == label:
                    return {'name': effect.name, 'joint': effect.spec.joint_name or None,
                            'label': label}  # fmt: skip
            name, _, rest = label.partition('[')
            joint = rest.rstrip(']').split(',')[0].strip() if rest else ''
            return {'name': name, 'joint': joint if joint in joints else None, 'label': label}

        return {
            'schema': SCHEMA,
            'robot': self.robot.name,
            'joints': joints,
            'target': self.target,
            'sources': self.sources,
            'model': self.augmented_model.to_dict(),
            'duration_s': self.duration_s,
            'noise': {
                'raw_std_nm': self.noise.raw_std_nm.tolist(),
                'filtered_std_nm': self.noise.filtered_std_nm.tolist(),
                'correlation_time_samples': self.noise.correlation_samples.tolist(),
                'band_hz': list(self.noise.band_hz),
            },
            'effective_samples': {k: v.tolist() for k, v in self.effective_samples.items()},
            'effects': [
                {
                    'name': e.name,
                    'joint': e.spec.joint_name or None,
                    'label': e.label,
                    'status': e.status,
                    'confidence': e.confidence,
                    'parameters': e.parameters,
                    'variance_explained': e.variance_explained.tolist(),
                    'variance_explained_total': e.variance_explained_total,
                    'contribution_rms_nm': e.contribution_rms_nm.tolist(),
                    'selection': e.selection,
                    'model': {
                        'spec': e.spec.to_dict(),
                        'coefficients': e.coefficients.tolist(),
                        'coefficients_ci': e.coefficients_ci.tolist(),
                    },
                }
                for e in self.effects
            ],
            'alias_sets': [
                {
                    'representative': alias.representative,
                    'members': [member(label) for label in alias.members],
                    'canonical_correlation': alias.canonical_correlation,
                    'unexplained_effective': alias.unexplained,
                }
                for alias in self.alias_sets
            ],
            'untestable': self.untestable,
            'unexplained_remainder': [r.__dict__ for r in self.remainder],
            'held_out_rmse_nm': {
                'before': self.rmse_before_nm.tolist(),
                'after': self.rmse_after_nm.tolist(),
                'waterfall': [
                    {'added': label, 'rmse_nm': rmse.tolist()} for label, rmse in self.waterfall
                ],
            },
            'location': [
                {
                    'joint': loc.joint,
                    'rms_nm': loc.rms_nm,
                    'explained_share': loc.explained_share,
                    'dominant': loc.dominant(),
                }
                for loc in self.location
            ],
            'stop_reason': self.stop_reason,
            'rejected': self.rejected,
            'config': self.config,
        }

    def to_json(self) -> str:
        """effects.json text."""
        return json.dumps(self.to_dict(), indent=1, default=_json_default) + '\n'


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')


def augmented_torque(
    result: DiagnosisResult,
    q: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    jerk: np.ndarray | None = None,
) -> np.ndarray:
    """Torque of the nominal model plus every effect of the refit model (aliases included).

    Args:
        result: a diagnosis.
        q: (N, n) joint positions [rad].
        v: (N, n) joint velocities [rad/s].
        a: (N, n) joint accelerations [rad/s^2].
        jerk: (N, n) joint jerks [rad/s^3] for the signal-delay term; zero if None (the term is
            then d tau / dq v + d tau / dv a only).

    Returns:
        (N, n) tau_u (or joint torque, per ``result.target``) [N*m].
    """
    return result.augmented_model.torque(q, v, a, jerk)


def filtered_prediction(
    result: DiagnosisResult, recording: Recording, *, with_effects: bool = True
) -> tuple[Dataset, np.ndarray]:
    """The refit (or nominal) model's torque along a recording, as the diagnosis meets the label.

    The model sees the recording's motion the way the diagnosis fitted it (``column_motion``),
    and its torque passes the label's zero-phase filter (the study's preprocessing: as is), so
    it compares sample by sample with the dataset's label ``tau`` (or with a noise-free torque
    filtered the same way).

    Returns:
        (the preprocessed dataset, (N, n) model torque filtered like the label [N*m]).
    """
    config = result.settings or DiagnosisConfig()
    (dataset,) = _as_datasets(recording, result.robot, config)
    q, v, a, jerk = column_motion(dataset)
    if with_effects:
        tau = augmented_torque(result, q, v, a, jerk)
    else:
        tau = result.nominal_model.evaluate(q, v, a).tau_nominal
    return dataset, _as_label(tau, dataset)


def evaluation_rows(
    dataset: Dataset, config: DiagnosisConfig | None = None
) -> dict[str, np.ndarray]:
    """Rows of the training and held-out parts that the diagnosis scores on.

    The filter's start-up transient is trimmed at both recording ends and after the train/test
    boundary (``DiagnosisConfig.edge_trim_s``).
    """
    config = config or DiagnosisConfig()
    return _kept_rows(dataset, _trim_samples(dataset, config), 1, config)


def _trim_samples(dataset: Dataset, config: DiagnosisConfig) -> int:
    cutoff = float(np.min(dataset.cutoff_hz))
    trim_s = config.edge_trim_s if config.edge_trim_s is not None else 1.0 / cutoff
    return round(trim_s / dataset.period_s)


# -- preparing the regression problem -------------------------------------------------------------
@dataclass(eq=False)
class _Recording:
    """One preprocessed recording with its nominal quantities and kept rows."""

    dataset: Dataset
    quantities: NominalQuantities
    smooth: NominalQuantities
    rows: dict[str, np.ndarray]
    nominal_filtered: np.ndarray


def _as_datasets(
    data: Recording | Dataset | Sequence[Recording | Dataset],
    robot: RobotConfig,
    config: DiagnosisConfig,
) -> list[Dataset]:
    """Preprocess recordings; check datasets."""
    items = [data] if isinstance(data, (Recording, Dataset)) else list(data)
    if not items:
        raise DatasetError('diagnosis: no recordings given')
    datasets: list[Dataset] = []
    for item in items:
        source = item.source
        if tuple(item.joints) != tuple(robot.joints):
            raise DatasetError(
                f'{source}: its joints {list(item.joints)} do not match the robot config '
                f'{robot.name} ({list(robot.joints)}); diagnose with the robot config the '
                'recording was made with'
            )
        if isinstance(item, Recording):
            datasets.append(prepare_dataset(item, robot, config.preprocess))
            continue
        if not math.isclose(item.period_s, robot.ipo_period_s, rel_tol=1e-9):
            raise DatasetError(
                f'{source}: sample period {item.period_s} s differs from the robot config '
                f'{robot.name} ({robot.ipo_period_s} s)'
            )
        datasets.append(item)
    for name in ('target', 'mode'):
        found = {getattr(d, name) for d in datasets}
        if len(found) > 1:
            raise DatasetError(f'diagnosis: recordings mix {name}s {sorted(found)}')
    return datasets


def column_motion(dataset: Dataset) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The motion (q, v, a, jerk), each (N, n), that regressor columns are built from.

    The dataset's fitting inputs: a controller's (recorded q, v smoothed far above the motion's
    band, a from them), so that columns are filtered once, like the label (building them from
    the filtered motion would filter the motion twice, which near motion onsets costs several
    N*m on heavily loaded joints); with the study's preprocessing, the filtered motion. The jerk
    is differentiated from a.
    """
    return dataset.q, dataset.v, dataset.a, differentiate(dataset.a, dataset.period_s)


def _as_label(x: np.ndarray, dataset: Dataset) -> np.ndarray:
    """A torque (N, n) along the dataset's recordings as the labels meet it.

    Filtered like the labels when fitting through the filter; as is for the study's way.
    """
    return dataset.filter_like_labels(x) if dataset.is_through_filter else np.array(x, float)


def _filter_columns(x: np.ndarray, dataset: Dataset) -> np.ndarray:
    """Filter each joint row of columns (N, n, k) like that joint's label (zero rows skipped).

    The same zero-phase Butterworth as ``preprocess.lowpass`` (forward-backward, default
    padding), each recording on its own.
    """
    out = np.zeros_like(x)
    for rows in dataset.recording_rows():
        for j in range(x.shape[1]):
            block = x[rows, j, :]
            if not np.any(block):
                continue
            sos = butterworth(float(dataset.cutoff_hz[j]), dataset.period_s, dataset.filter_order)
            out[rows, j, :] = signal.sosfiltfilt(sos, block, axis=0)
    return out


def _kept_rows(
    dataset: Dataset, trim: int, step: int, config: DiagnosisConfig
) -> dict[str, np.ndarray]:
    n_samples = len(dataset.q)
    train = np.arange(trim, dataset.n_train, step)
    test = np.arange(dataset.n_train + trim, n_samples - trim, step)
    return {'train': train, 'test': test}


class _Problem:
    """Filtered residual, candidate columns and weights over all recordings."""

    def __init__(
        self, datasets: list[Dataset], robot: RobotConfig, config: DiagnosisConfig
    ) -> None:
        self.robot = robot
        self.config = config
        self.datasets = datasets
        self.model = NominalModel(robot, datasets[0].target)
        first = datasets[0]
        self.cutoff = np.asarray(first.cutoff_hz, dtype=float)
        self.period = first.period_s
        self.noise = self._noise()
        tau = self.noise.correlation_samples
        self.step = max(1, int(tau.min() // 6))
        self.trim = _trim_samples(first, config)
        self.weights = self.step / (self.noise.filtered_std_nm**2 * tau)
        self.library_preview: list[EffectSpec] = []
        self.recordings: list[_Recording] = []
        #: Link-side terms (spec, physical coefficients) the model-load friction sees.
        self.link_terms: list[tuple[EffectSpec, np.ndarray]] = []
        self._quantities_for_library()

    def _noise(self) -> NoiseEstimate:
        estimates = [
            estimate_noise(d.tau_raw, d.cutoff_hz, d.period_s, d.filter_order)
            for d in self.datasets
        ]
        lengths = np.array([len(d.tau_raw) for d in self.datasets], dtype=float)
        share = lengths / lengths.sum()

        def pooled(values: list[np.ndarray]) -> np.ndarray:
            return np.sqrt(np.sum([s * x**2 for s, x in zip(share, values, strict=True)], axis=0))

        raw = pooled([e.raw_std_nm for e in estimates])
        filtered = pooled([e.filtered_std_nm for e in estimates])
        # A perfectly clean label (no noise at all) still needs a finite weight.
        floor = 1e-6 * np.maximum(self.robot.limits.torque, 1.0)
        return NoiseEstimate(
            raw, np.maximum(filtered, floor), estimates[0].correlation_samples,
            estimates[0].band_hz,
        )  # fmt: skip

    def _quantities_for_library(self) -> None:
        probe = [EffectSpec(name) for name in self.config.effects]
        derivatives, regressor = needs_derivatives(probe), needs_regressor(probe)
        all_rows = [_kept_rows(d, self.trim, self.step, self.config) for d in self.datasets]
        self._check_length(all_rows)
        for dataset, rows in zip(self.datasets, all_rows, strict=True):
            q, v, a, jerk = column_motion(dataset)
            quantities = self.model.evaluate(
                q, v, a, jerk, derivatives=derivatives, regressor=regressor
            )
            nominal = _as_label(quantities.tau_nominal, dataset)
            smooth = self._smooth(dataset)
            self.recordings.append(_Recording(dataset, quantities, smooth, rows, nominal))
        self.library = build_library(self.model, self.joined_quantities(), self.config)

    def _check_length(self, all_rows: list[dict[str, np.ndarray]]) -> None:
        """Refuse recordings whose parts hold too few independent samples (all together)."""
        for part in PARTS:
            count = sum(len(rows[part]) for rows in all_rows)
            n_eff = count * self.step / self.noise.correlation_samples
            if n_eff.min() >= self.config.min_effective_samples:
                continue
            n_total = sum(len(d.q) for d in self.datasets)
            n_train = sum(d.n_train for d in self.datasets)
            share = (n_total - n_train if part == 'test' else n_train) / n_total
            needed = (
                self.config.min_effective_samples
                * self.noise.correlation_samples.max()
                * self.period
                / share
                + 3 * self.trim * self.period
            )
            total = sum(len(d.q) for d in self.datasets) * self.period
            raise DatasetError(
                f'{", ".join(d.source for d in self.datasets)}: {total:.1f} s is too short to '
                f'diagnose: the {part} part holds {n_eff.min():.1f} independent samples on the '
                f'slowest-filtered joint, fewer than {self.config.min_effective_samples:g}; '
                f'record at least {needed:.0f} s'
            )

    def _smooth(self, dataset: Dataset) -> NominalQuantities:
        """Quantities along the filtered motion, for the testability of switching effects."""
        q, v, a = dataset.study.q, dataset.study.v, dataset.study.a
        if 'load_dependent_friction' in self.config.effects:
            return self.model.evaluate(q, v, a)
        zeros = np.zeros_like(q)  # only the load-dependent columns read the torques
        return NominalQuantities(q, v, a, zeros, zeros, zeros, zeros)

    def joined_quantities(self) -> NominalQuantities:
        """Training rows of every recording, for choices that look at the whole excitation."""

        def join(key: str) -> np.ndarray:
            return np.concatenate(
                [getattr(r.quantities, key)[r.rows['train']] for r in self.recordings]
            )

        return NominalQuantities(
            q=join('q'),
            v=join('v'),
            a=join('a'),
            jerk=join('jerk'),
            tau_rigid=join('tau_rigid'),
            tau_rotor=join('tau_rotor'),
            tau_nominal=join('tau_nominal'),
        )

    def part(self, key: str, part: str) -> np.ndarray:
        """A dataset quantity on one part's kept rows, over every recording."""
        return np.concatenate([getattr(r.dataset, key)[r.rows[part]] for r in self.recordings])

    def label(self, part: str) -> np.ndarray:
        """(M, n) filtered label [N*m] on one part's kept rows."""
        return np.concatenate([r.dataset.tau[r.rows[part]] for r in self.recordings])

    def residual(self, part: str) -> np.ndarray:
        """(M, n) filtered label minus filtered nominal [N*m] on one part's kept rows."""
        return np.concatenate(
            [
                r.dataset.tau[r.rows[part]] - r.nominal_filtered[r.rows[part]]
                for r in self.recordings
            ]
        )

    def columns(self, spec: EffectSpec) -> tuple[dict[str, np.ndarray], np.ndarray, float]:
        """Filtered columns per part, raw training columns and the filter's retention."""
        filtered: dict[str, list[np.ndarray]] = {'train': [], 'test': []}
        raw_train = []
        raw_energy = kept_energy = 0.0
        switching = spec.name in SWITCHING_EFFECTS
        for r in self.recordings:
            quantities = self._loaded(r) if uses_model_load(spec) else r.quantities
            x = effect_columns(spec, quantities, self.model)
            xf = _filter_columns(x, r.dataset) if r.dataset.is_through_filter else x
            for part in ('train', 'test'):
                filtered[part].append(xf[r.rows[part]])
            train = r.rows['train']
            raw_train.append(x[train])
            if switching:
                # Judge the signature on the smooth (filtered) motion: sensor noise in the
                # recorded motion would pass for high-frequency content.
                smooth = effect_columns(spec, r.smooth, self.model)
                raw_energy += float(np.sum(smooth[train] ** 2))
                kept_energy += float(np.sum(_filter_columns(smooth, r.dataset)[train] ** 2))
        retention = kept_energy / raw_energy if raw_energy > 0 else (0.0 if switching else 1.0)
        return (
            {part: np.concatenate(blocks) for part, blocks in filtered.items()},
            np.concatenate(raw_train),
            retention,
        )

    def _loaded(self, r: _Recording) -> NominalQuantities:
        """A recording's quantities with the link torque of the nominal model plus link terms."""
        link = r.quantities.tau_rigid.copy()
        for spec, theta in self.link_terms:
            link += effect_columns(spec, r.quantities, self.model) @ theta
        return replace(r.quantities, tau_rigid=link)

    def times(self, part: str) -> np.ndarray:
        """Times [s] of one part's kept rows; later recordings follow the earlier ones."""
        out, offset = [], 0.0
        for r in self.recordings:
            t = (r.dataset.stamps_ns - r.dataset.stamps_ns[0]) * 1e-9
            out.append(t[r.rows[part]] + offset)
            offset += float(t[-1]) + self.period
        return np.concatenate(out)

    def n_effective(self, part: str) -> np.ndarray:
        """(n,) effective samples per joint on one part."""
        rows = sum(len(r.rows[part]) for r in self.recordings)
        return rows * self.step / self.noise.correlation_samples


# -- the diagnosis --------------------------------------------------------------------------------
def run_diagnosis(
    data: Recording | Dataset | Sequence[Recording | Dataset],
    robot: RobotConfig,
    config: DiagnosisConfig | None = None,
) -> DiagnosisResult:
    """The diagnosis without writing anything (see ``diagnose``)."""
    config = config or DiagnosisConfig()
    problem = _Problem(_as_datasets(data, robot, config), robot, config)
    candidates = _Candidates(problem)
    y = {part: problem.residual(part) for part in PARTS}
    n_eff = {part: problem.n_effective(part) for part in PARTS}
    selection = forward_select(
        candidates.design(y, n_eff),
        candidates.testable,
        candidates.plausible,
        significance=config.significance,
        max_groups=config.max_effects,
        conflicts=candidates.conflicts,
        noise_significance=config.noise_significance,
        noise_tolerance=config.noise_tolerance,
    )
    selected = candidates.refine(selection.selected, y, n_eff)
    design = candidates.design(y, n_eff)

    def aliases_of(groups: list[str]) -> list[AliasSet]:
        return find_aliases(
            design,
            groups,
            candidates.testable,
            candidates.plausible,
            significance=config.alias_significance,
            variants=candidates.variants,
        )

    aliases = aliases_of(selected)
    specific = candidates.special_cases(selected, aliases)
    if specific != selected:
        selected = candidates.refine(specific, y, n_eff)
        design = candidates.design(y, n_eff)
        aliases = aliases_of(selected)
    aliases = candidates.without_generalisations(aliases)
    return _assemble(
        problem, candidates, design, selection=selection, selected=selected, aliases=aliases
    )


class _Candidates:
    """The library's columns on every part, their testability and plausibility rules."""

    def __init__(self, problem: _Problem) -> None:
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
        quantities = problem.joined_quantities()
        self.facts = PlausibilityFacts(
            rigid_rms=np.sqrt(np.mean(quantities.tau_rigid**2, axis=0)),
            gravity=model.dynamics.gravity(quantities.q),
            moving_mass_kg=model.dynamics.total_moving_mass(),
            body_parameters=model.dynamics.inertial_parameters().reshape(-1, 10),
        )

    def design(self, y: dict[str, np.ndarray], n_eff: dict[str, np.ndarray]) -> Design:
        """The regression problem over the testable candidates.

        The link parameters' changes (inertial_parameter_error) carry the CAD prior of
        ``physics.base_parameters``: a URDF's masses and centres of mass are good to ten per
        cent and a few centimetres, so the data move them only as far as they show.
        """
        columns = {label: self.columns[label] for label in self.testable}
        priors = {}
        for label in self.testable:
            name = self.specs[label].name
            if name == 'inertial_parameter_error':
                priors[label] = self._cad_precision(self.specs[label])
            elif name == 'torque_constant_scale':
                # A datasheet torque constant's tolerance: it and the link masses trade a
                # common scale that only the priors settle.
                priors[label] = np.array([[1.0 / LABEL_GAIN_STD**2]])
        return Design(y, columns, self.problem.weights, n_eff, priors)

    def _cad_precision(self, spec: EffectSpec) -> np.ndarray:
        """Prior precision of the base-direction coefficients of the link parameters' change."""
        directions = np.asarray(spec.settings['base_directions'])
        theta0 = self.problem.model.dynamics.inertial_parameters()
        std = CadPrior().std(theta0)
        # A change d theta ~ N(0, diag(std^2)) has base coordinates c = pinv(D) d theta.
        mapping = np.linalg.pinv(directions)
        covariance = (mapping * std**2) @ mapping.T
        return np.linalg.inv(covariance)

    def plausible(self, design: Design, fit: Fit) -> dict[str, tuple[bool, str]]:
        """The plausibility rule's verdict on every group of a fit."""
        out = {}
        for group in fit.groups:
            theta = design.physical(fit, group)
            out[group] = plausibility(
                self.specs[group],
                theta,
                self.raw[group] @ theta,
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

    def conflicts(self, label: str, selected: Sequence[str]) -> bool:
        """Two Stribeck velocities of one joint never enter together."""
        if self.specs[label].name != 'stribeck_friction':
            return False
        return any(self.variants(label, other) for other in selected)

    def refine(
        self, selected: Sequence[str], y: dict[str, np.ndarray], n_eff: dict[str, np.ndarray]
    ) -> list[str]:
        """Tune the selected effects' nonlinear settings; the selection's new labels.

        Stribeck velocity, payload COM and balancer geometry, then the friction's load.
        """
        selected = list(selected)
        for index, label in enumerate(list(selected)):
            spec = self.specs[label]
            if spec.name not in ('stribeck_friction', 'payload_mass', 'gravity_spring'):
                continue
            others = {g: self.columns[g] for g in selected if g != label}
            refined = _refine(self.problem, others, spec, y=y, n_eff=n_eff)
            if refined is None:
                continue
            self._swap(label, refined)
            selected[index] = refined.label
        return self._load_on_model(selected, y, n_eff)

    def _swap(self, label: str, refined: EffectSpec) -> None:
        """Put a refined spec (and its columns) in the place of a candidate."""
        new = refined.label
        self.specs[new] = refined
        self.columns[new], self.raw[new], _ = self.problem.columns(refined)
        self.testable = [new if t == label else t for t in self.testable if t != new or t == label]

    def _load_on_model(
        self, selected: list[str], y: dict[str, np.ndarray], n_eff: dict[str, np.ndarray]
    ) -> list[str]:
        """Let selected load-dependent friction see the model's link torque, not the URDF's.

        A payload, a balancer or changed link parameters change the torque the gears carry;
        with the URDF's alone the friction coefficient soaks up their share (``uses_model_load``).
        """
        specs = [self.specs[label] for label in selected]
        loads = [i for i, s in enumerate(specs) if s.name == 'load_dependent_friction']
        link = [
            label for label, s in zip(selected, specs, strict=True) if s.name in LINK_SIDE_EFFECTS
        ]
        if not loads or not link:
            return selected
        design = self.design(y, n_eff)
        fit = design.fit(selected)
        self.problem.link_terms = [(self.specs[g], design.physical(fit, g)) for g in link]
        selected = list(selected)
        for i in loads:
            refined = specs[i].replace_settings(load='model')
            self._swap(selected[i], refined)
            selected[i] = refined.label
        return selected

    def _general_of(self, special: str, general: str) -> bool:
        return SPECIAL_CASES.get(self.specs[special].name) == self.specs[general].name

    def special_cases(self, selected: Sequence[str], aliases: Sequence[AliasSet]) -> list[str]:
        """``selected`` with each general effect replaced by a special case that mimics it.

        Of several, the one that leaves least of the general effect's contribution.
        """
        out = list(selected)
        for alias in aliases:
            special = [m for m in alias.members[1:] if self._general_of(m, alias.representative)]
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


def _waterfall(
    design: Design, selected: Sequence[str], weights: np.ndarray
) -> tuple[list[tuple[str, np.ndarray]], dict[str, np.ndarray], dict[str, float]]:
    """Held-out RMSE after each added effect, and the held-out variance each one removed.

    The share is of the nominal residual's held-out variance, per joint and over all joints
    weighted by the noise.
    """
    previous = design.residual(design.fit([]), 'test')
    base = np.mean(previous**2, axis=0)
    base_total = float(np.sum(weights * np.sum(previous**2, axis=0)))
    waterfall, explained, explained_total = [], {}, {}
    for k, label in enumerate(selected, start=1):
        residual = design.residual(design.fit(selected[:k]), 'test')
        waterfall.append((label, _rmse(residual)))
        gain = np.mean(previous**2, axis=0) - np.mean(residual**2, axis=0)
        explained[label] = np.where(base > 0, gain / np.where(base > 0, base, 1.0), 0.0)
        total = float(
            np.sum(weights * (np.sum(previous**2, axis=0) - np.sum(residual**2, axis=0)))
        )
        explained_total[label] = total / base_total if base_total > 0 else 0.0
        previous = residual
    return waterfall, explained, explained_total


def _assemble(
    problem: _Problem,
    candidates: _Candidates,
    design: Design,
    *,
    selection: SelectionResult,
    selected: list[str],
    aliases: list[AliasSet],
) -> DiagnosisResult:
    """Refit with the selected effects and collect what the report shows."""
    robot, config = problem.robot, problem.config
    final = design.fit(selected)
    waterfall, explained, explained_total = _waterfall(design, selected, problem.weights)
    remainder = _remainder(problem, design, final, config)
    members = {label for alias in aliases for label in alias.members}
    t_crit = float(stats.t.ppf(0.975, max(design.n_eff_train - final.rank, 1.0)))
    effects = []
    for step, label in zip(selection.steps, selected, strict=True):
        spec = candidates.specs[label]
        theta = design.physical(final, label)
        interval_covariance = t_crit**2 * design.physical_covariance(final, label)
        half = np.sqrt(np.clip(np.diag(interval_covariance), 0, None))
        rms = _rmse(np.concatenate([design.contribution(final, label, p) for p in PARTS]))
        # Low confidence: a structured remainder on one of its joints outweighs what it explains.
        low = any(
            r.structured and 0 < rms[robot.joints.index(r.joint)] < r.rms_nm for r in remainder
        )
        effects.append(
            FoundEffect(
                spec=spec,
                status='alias' if label in members else 'found',
                confidence='low' if low else 'high',
                coefficients=theta,
                coefficients_ci=np.stack([theta - half, theta + half], axis=1),
                parameters=describe_parameters(
                    spec, theta, half, problem.model, interval_covariance
                ),
                contribution_rms_nm=rms,
                variance_explained=explained[label],
                variance_explained_total=explained_total[label],
                selection={
                    'f_statistic': step.f_statistic,
                    'p_value': step.p_value,
                    'delta_bic': step.delta_bic,
                    'held_out_gain': step.held_out_gain,
                    'columns': step.extra_rank,
                },
            )
        )
    rejected = None
    if selection.rejected is not None:
        r = selection.rejected
        rejected = {
            'label': r.label,
            'p_value': r.p_value,
            'level': selection.level,
            'delta_bic': r.delta_bic,
            'held_out_gain': r.held_out_gain,
            'plausible': r.plausible,
            'reason': r.reason,
        }
    times = {part: problem.times(part) for part in PARTS}
    location = locate_residual(
        design.y['train'],
        problem.part('q', 'train'),
        problem.part('v', 'train'),
        problem.part('a', 'train'),
        load=problem.joined_quantities().tau_rigid,
        t=times['train'],
        joints=robot.joints,
    )
    series = {
        'time_s': np.concatenate([times[part] for part in PARTS]),
        'is_test': np.concatenate([np.full(len(times[part]), part == 'test') for part in PARTS]),
        'label': np.concatenate([problem.label(part) for part in PARTS]),
        'residual_before': np.concatenate([design.y[part] for part in PARTS]),
        'residual_after': np.concatenate([design.residual(final, part) for part in PARTS]),
    }
    return DiagnosisResult(
        robot=robot,
        target=problem.datasets[0].target,
        sources=[d.source for d in problem.datasets],
        duration_s=float(sum(len(d.q) for d in problem.datasets) * problem.period),
        noise=problem.noise,
        effective_samples=design.n_effective,
        effects=effects,
        alias_sets=aliases,
        untestable=candidates.untestable_summary(),
        remainder=remainder,
        rmse_before_nm=_rmse(design.residual(design.fit([]), 'test')),
        rmse_after_nm=_rmse(design.residual(final, 'test')),
        waterfall=waterfall,
        location=location,
        stop_reason=selection.stop_reason,
        rejected=rejected,
        config=config.to_dict()
        | {'n_candidates': len(candidates.testable), 'level': selection.level},
        series=series,
        settings=config,
    )


def _rmse(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=0))


def _remainder(
    problem: _Problem, design: Design, fit: Fit, config: DiagnosisConfig
) -> list[Remainder]:
    _, ratio, p_values = noise_consistency(
        design, fit, config.noise_significance, config.noise_tolerance
    )
    residual = np.concatenate([design.residual(fit, part) for part in ('train', 'test')])
    rms = _rmse(residual)
    train = design.residual(fit, 'train')
    out = []
    for j, joint in enumerate(problem.robot.joints):
        tau_acf = integrated_autocorrelation(train[:, j]) * problem.step
        correlation = tau_acf / problem.noise.correlation_samples[j]
        # Larger than the noise (variance test and size), or above it and correlated far
        # beyond the filter's correlation time (structure, where filtered noise is white).
        larger = p_values[j] <= config.noise_significance and ratio[j] > config.noise_tolerance
        correlated = correlation > config.structure_correlation_ratio and ratio[j] > 1.1
        structured = bool(larger or correlated)
        out.append(
            Remainder(
                joint=joint,
                rms_nm=float(rms[j]),
                noise_nm=float(problem.noise.filtered_std_nm[j]),
                ratio=float(ratio[j]),
                p_value=float(p_values[j]),
                correlation_ratio=float(correlation),
                structured=structured,
            )
        )
    return out


def _refine(
    problem: _Problem,
    others: dict[str, dict[str, np.ndarray]],
    spec: EffectSpec,
    *,
    y: dict[str, np.ndarray],
    n_eff: dict[str, np.ndarray],
) -> EffectSpec | None:
    """Tune a selected effect's nonlinear setting on the training part, the others kept."""

    def rss_of(candidate: EffectSpec) -> tuple[float, Design, Fit]:
        cols, _, _ = problem.columns(candidate)
        small = Design(y, {**others, candidate.label: cols}, problem.weights, n_eff)
        fit = small.fit([*others, candidate.label])
        return fit.rss['train'], small, fit

    if spec.name == 'stribeck_friction':
        start = float(spec.settings['velocity'])

        def objective(log_vs: float) -> float:
            return rss_of(spec.replace_settings(velocity=float(math.exp(log_vs))))[0]

        best = optimize.minimize_scalar(
            objective,
            bounds=(math.log(start / 2.5), math.log(start * 2.5)),
            method='bounded',
            options={'xatol': 0.02},
        )
        if best.fun < rss_of(spec)[0]:
            return spec.replace_settings(velocity=round(float(math.exp(best.x)), 5))
        return None
    if spec.name == 'gravity_spring' and 'ratio' in spec.settings:
        # The balancer's geometry: the best of a grid of arm ratios and phases, then refined
        # together (an encoder zero error shifts the phase by milliradians).
        def spring_rss(geometry: np.ndarray) -> float:
            ratio = float(np.clip(geometry[0], 0.05, 0.98))
            return rss_of(spec.replace_settings(ratio=ratio, phase_rad=float(geometry[1])))[0]

        grid = [np.array([r, p]) for r in BALANCER_RATIOS for p in BALANCER_PHASES]
        start = min(grid, key=spring_rss)
        best = optimize.minimize(
            spring_rss,
            start,
            method='Nelder-Mead',
            options={
                'xatol': 1e-4,
                'fatol': 1e-9,
                'initial_simplex': start + np.array([[0.0, 0.0], [0.05, 0.0], [0.0, 0.05]]),
            },
        )
        if best.fun < rss_of(spec)[0]:
            ratio = round(float(np.clip(best.x[0], 0.05, 0.98)), 5)
            return spec.replace_settings(ratio=ratio, phase_rad=round(float(best.x[1]), 5))
        return None
    if spec.name == 'payload_mass':
        current = spec
        for _ in range(6):
            _, small, fit = rss_of(current)
            theta = small.physical(fit, current.label)
            if theta[0] <= 0:
                return None
            com = (np.asarray(theta[1:4]) / theta[0]).tolist()
            if np.allclose(com, current.settings['com_guess_m'], atol=1e-4):
                break
            current = current.replace_settings(com_guess_m=com)
        return current
    return None
