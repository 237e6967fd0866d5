"""The diagnosis's regression problem: filtered residual, candidate columns and row weights.

Every recording is preprocessed, the nominal model evaluated on a controller's inputs, the rows
kept where the zero-phase filter has settled; candidate columns are filtered exactly like the
label (or, with the study's preprocessing, built on the filtered motion).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar, cast

import numpy as np
from scipy import signal

from id_learning.dataset.preprocess import Dataset, prepare_dataset
from id_learning.dataset.recording import Recording, check_recording_content
from id_learning.dataset.signals import butterworth, differentiate, time_shifted
from id_learning.dataset.statistics import (
    NoiseEstimate,
    estimate_noise,
)
from id_learning.diagnosis.candidates import (
    build_library,
)
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.design import PARTS, Design
from id_learning.diagnosis.standstill import StandstillProjection
from id_learning.errors import DatasetError
from id_learning.physics.effects import effect
from id_learning.physics.nominal import NominalModel, NominalQuantities
from id_learning.physics.terms import (
    EffectSpec,
    delay_about,
    effect_columns,
    load_slope,
    needs_derivatives,
    needs_regressor,
    uses_model_load,
    whole_model_delay,
    whole_model_scale,
)
from id_learning.robot.config import RobotConfig

_T = TypeVar('_T')

__all__ = [
    'PreparedRecording',
    'ResidualProblem',
    'as_datasets',
    'as_label',
    'column_motion',
    'evaluation_rows',
    'filter_columns',
    'kept_rows',
    'trim_samples',
]


def evaluation_rows(
    dataset: Dataset, config: DiagnosisConfig | None = None
) -> dict[str, np.ndarray]:
    """Rows of the training and held-out parts that the diagnosis scores on.

    The filter's start-up transient is trimmed at both recording ends and after the train/test
    boundary (``DiagnosisConfig.edge_trim_s``).
    """
    config = config or DiagnosisConfig()
    return kept_rows(dataset, trim_samples(dataset, config), 1, config)


def trim_samples(dataset: Dataset, config: DiagnosisConfig) -> int:
    """Samples dropped at each recording edge, where the zero-phase filter starts up."""
    cutoff = float(np.min(dataset.cutoff_hz))
    trim_s = config.edge_trim_s if config.edge_trim_s is not None else 1.0 / cutoff
    return round(trim_s / dataset.period_s)


@dataclass(eq=False)
class PreparedRecording:
    """One preprocessed recording with its nominal quantities and kept rows."""

    dataset: Dataset
    quantities: NominalQuantities
    smooth: NominalQuantities
    rows: dict[str, np.ndarray]
    nominal_filtered: np.ndarray


def as_datasets(
    data: Recording | Dataset | Sequence[Recording | Dataset],
    robot: RobotConfig,
    config: DiagnosisConfig,
) -> list[Dataset]:
    """Preprocess recordings; check datasets.

    Raises:
        DatasetError: a recording of other joints, a label constant in every sample, no joint
            moving (``dataset.content``), mixed targets or modes.
    """
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
            # The refusals of load_recording for recordings made in code (its warnings were
            # logged when a bag was loaded).
            check_recording_content(item, config.preprocess.target, warn=False)
            datasets.extend(
                prepare_dataset(segment, robot, config.preprocess, segment=k)
                for k, segment in enumerate(item.segments())
            )
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


def as_label(x: np.ndarray, dataset: Dataset) -> np.ndarray:
    """A torque (N, n) along the dataset's recordings as the labels meet it.

    Filtered like the labels when fitting through the filter; as is for the study's way.
    """
    return dataset.filter_like_labels(x) if dataset.is_through_filter else np.array(x, float)


def filter_columns(x: np.ndarray, dataset: Dataset) -> np.ndarray:
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


def kept_rows(
    dataset: Dataset, trim: int, step: int, config: DiagnosisConfig
) -> dict[str, np.ndarray]:
    """Training and held-out rows, edges trimmed and every ``step``-th kept."""
    n_samples = len(dataset.q)
    train = np.arange(trim, dataset.n_train, step)
    test = np.arange(dataset.n_train + trim, n_samples - trim, step)
    return {'train': train, 'test': test}


class ResidualProblem:
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
        self.trim = trim_samples(first, config)
        self.weights = self.step / (self.noise.filtered_std_nm**2 * tau)
        self.library_preview: list[EffectSpec] = []
        self.recordings: list[PreparedRecording] = []
        #: Link-side terms (spec, physical coefficients) the model-load friction sees.
        self.link_terms: list[tuple[EffectSpec, np.ndarray]] = []
        #: Model-load frictions (spec, coefficient) whose share of the link torque every
        #: link-side column carries on their joint (``_load_share``).
        self.load_terms: list[tuple[EffectSpec, np.ndarray]] = []
        #: Terms (spec, physical coefficients) whose torque a delay of the model's form delays
        #: and a torque-constant error of the model's form scales (``CandidateSet.whole_model``).
        self.rate_terms: list[tuple[EffectSpec, np.ndarray]] = []
        self.scale_terms: list[tuple[EffectSpec, np.ndarray]] = []
        #: What the term lists now set give along each recording (``_remembered``).
        self._memo: dict[tuple[str | int, ...], tuple[tuple[object, ...], Any]] = {}
        self._quantities_for_library()

    def _noise(self) -> NoiseEstimate:
        estimates = [
            estimate_noise(d.tau_raw, d.cutoff_hz, d.period_s, d.filter_order)
            for d in self.datasets
        ]
        lengths = np.array([len(d.tau_raw) for d in self.datasets], dtype=float)
        share = lengths / lengths.sum()

        def pooled(values: list[np.ndarray]) -> np.ndarray:
            out: np.ndarray = np.sqrt(
                np.sum([s * x**2 for s, x in zip(share, values, strict=True)], axis=0)
            )
            return out

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
        gravity = self._reads_load()
        all_rows = [kept_rows(d, self.trim, self.step, self.config) for d in self.datasets]
        self._check_length(all_rows)
        for dataset, rows in zip(self.datasets, all_rows, strict=True):
            q, v, a, jerk = column_motion(dataset)
            quantities = self.model.evaluate(
                q, v, a, jerk, derivatives=derivatives, regressor=regressor, gravity=gravity
            )
            nominal = as_label(quantities.tau_nominal, dataset)
            smooth = self._smooth(dataset)
            self.recordings.append(PreparedRecording(dataset, quantities, smooth, rows, nominal))
        self.standstill = StandstillProjection(
            [(r.dataset, r.rows) for r in self.recordings],
            self.config.standstill_velocity,
            self.config.standstill_min_s,
        )
        self.library = build_library(self.model, self.joined_quantities(), self.config)

    def _check_length(self, all_rows: list[dict[str, np.ndarray]]) -> None:
        """Refuse recordings whose parts hold too few independent samples (all together).

        The length advised is the one at which both parts would hold enough: each part keeps
        its share of the samples less a fixed number at its ends (trimmed), so its independent
        samples grow with the recorded time beyond those (plus 10 %: the noise's correlation
        time is itself an estimate).
        """
        n_total = sum(len(d.q) for d in self.datasets)
        n_train = sum(d.n_train for d in self.datasets)
        total = n_total * self.period
        short, needed = {}, 0.0
        for part in PARTS:
            count = sum(len(rows[part]) for rows in all_rows)
            n_eff = float((count * self.step / self.noise.correlation_samples).min())
            if n_eff >= self.config.min_effective_samples:
                continue
            short[part] = n_eff
            share = (n_total - n_train if part == 'test' else n_train) / n_total
            kept = count * self.step  # recorded samples the kept rows stand for
            lost = share * n_total - kept  # what its trimmed ends cost, whatever the length
            wanted = kept * self.config.min_effective_samples / max(n_eff, 1e-9) * 1.1
            needed = max(needed, (wanted + lost) / share * self.period)
        if not short:
            return
        part, n_eff = min(short.items(), key=lambda item: item[1])
        raise DatasetError(
            f'{", ".join(d.source for d in self.datasets)}: {total:.1f} s is too short to '
            f'diagnose: the {" and ".join(short)} part(s) hold too few independent samples on '
            f'the slowest-filtered joint ({part}: {n_eff:.1f}, fewer than '
            f'{self.config.min_effective_samples:g}); record at least {math.ceil(needed)} s'
        )

    def _smooth(self, dataset: Dataset) -> NominalQuantities:
        """Quantities along the filtered motion, for the testability of switching effects."""
        q, v, a = dataset.study.q, dataset.study.v, dataset.study.a
        if self._reads_load():
            return self.model.evaluate(q, v, a, gravity=True)
        zeros = np.zeros_like(q)  # only the load-dependent columns read the torques
        return NominalQuantities(q, v, a, zeros, zeros, zeros, zeros, tau_gravity=zeros)

    def _reads_load(self) -> bool:
        """Whether a candidate grows with a load (link torque or gravity's): only friction does."""
        return any(effect(name).reads_link_torque for name in self.config.effects)

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
            tau_gravity=join('tau_gravity') if self._reads_load() else None,
        )

    def part(self, key: str, part: str) -> np.ndarray:
        """A dataset quantity on one part's kept rows, over every recording."""
        return np.concatenate([getattr(r.dataset, key)[r.rows[part]] for r in self.recordings])

    def label(self, part: str) -> np.ndarray:
        """(M, n) filtered label [N*m] on one part's kept rows."""
        return np.concatenate([r.dataset.tau[r.rows[part]] for r in self.recordings])

    def residual(self, part: str) -> np.ndarray:
        """(M, n) filtered label minus filtered nominal [N*m] on one part's kept rows.

        The training part without what the joints' standstills hold (``standstill``): a fit
        nuisance. The test part keeps it, so held-out errors are those of a model that predicts.
        """
        y = np.concatenate(
            [
                r.dataset.tau[r.rows[part]] - r.nominal_filtered[r.rows[part]]
                for r in self.recordings
            ]
        )
        return self.standstill.project(y) if part == 'train' else y

    def columns(self, spec: EffectSpec) -> tuple[dict[str, np.ndarray], np.ndarray, float]:
        """Filtered columns per part, raw training columns and the filter's retention."""
        filtered: dict[str, list[np.ndarray]] = {'train': [], 'test': []}
        raw_train = []
        raw_energy = kept_energy = 0.0
        switching = effect(spec.name).switching
        for r in self.recordings:
            if delay_about(spec) > 0:
                x, xf = self._delay_secant(r, spec)
            else:
                quantities = self._loaded(r) if uses_model_load(spec) else r.quantities
                x = effect_columns(spec, quantities, self.model)
                if effect(spec.name).link_side and self.load_terms:
                    x = x * (1.0 + self._load_share(r))[:, :, None]
                if whole_model_delay(spec):
                    x = x - self._terms_rate(r)[:, :, None]
                if whole_model_scale(spec):
                    x = x.copy()
                    x[:, spec.joint, 0] += self._terms_torque(r, self.scale_terms)[:, spec.joint]
                xf = filter_columns(x, r.dataset) if r.dataset.is_through_filter else x
            for part in ('train', 'test'):
                filtered[part].append(xf[r.rows[part]])
            train = r.rows['train']
            raw_train.append(x[train])
            if switching:
                # Judge the signature on the smooth (filtered) motion: sensor noise in the
                # recorded motion would pass for high-frequency content.
                smooth = effect_columns(spec, r.smooth, self.model)
                raw_energy += float(np.sum(smooth[train] ** 2))
                kept_energy += float(np.sum(filter_columns(smooth, r.dataset)[train] ** 2))
        retention = kept_energy / raw_energy if raw_energy > 0 else (0.0 if switching else 1.0)
        return (
            {
                part: self.standstill.project(np.concatenate(blocks))
                if part == 'train'
                else np.concatenate(blocks)
                for part, blocks in filtered.items()
            },
            np.concatenate(raw_train),
            retention,
        )

    def design(
        self,
        y: dict[str, np.ndarray],
        columns: dict[str, dict[str, np.ndarray]],
        n_eff: dict[str, np.ndarray],
        priors: dict[str, np.ndarray] | None = None,
    ) -> Design:
        """The regression of ``y`` on ``columns`` with this problem's row weights.

        Every fit holds the model-load friction's linearisation constant, if any (``load_offset``).
        """
        return Design(y, columns, self.weights, n_eff, priors, offset=self.load_offset())

    def load_offset(self) -> dict[str, np.ndarray] | None:
        """Per part, (M, n) the constant of the model-load friction's linearisation [N*m].

        A model-load friction c |L| s(v), with L the URDF's link torque plus the link-side
        terms X theta, is bilinear in c and theta. About the last fit (c0, theta0) it is
        c |L0| s(v) + c0 sign(L0) s(v) X (theta - theta0): its own column on the last fit's
        load, a share c0 sign(L0) s(v) of every link-side column (``_load_share``), so that
        a payload, a balancer or a link change and the friction they load are fitted together,
        and this constant, -c0 sign(L0) s(v) X theta0, which every fit holds (``Design``).
        ``CandidateSet.load_on_model`` iterates to where the fit settles (Gauss-Newton).
        None without model-load friction.
        """
        if not self.load_terms:
            return None

        def offset() -> dict[str, np.ndarray]:
            blocks: dict[str, list[np.ndarray]] = {part: [] for part in PARTS}
            for r in self.recordings:
                held = self._loaded(r).tau_rigid - r.quantities.tau_rigid
                x = (-self._load_share(r) * held)[:, :, None]
                xf = filter_columns(x, r.dataset) if r.dataset.is_through_filter else x
                for part in PARTS:
                    blocks[part].append(xf[r.rows[part], :, 0])
            out = {part: np.concatenate(b) for part, b in blocks.items()}
            out['train'] = self.standstill.project(out['train'])
            return out

        return self._remembered('load offset', (self, self.load_terms, self.link_terms), offset)

    def _load_share(self, r: PreparedRecording) -> np.ndarray:
        """(N, n) c0 sign(L0) s(v) of the model-load frictions: their share of a link torque."""

        def share() -> np.ndarray:
            out = np.zeros_like(r.quantities.q)
            loaded = self._loaded(r)
            for spec, theta in self.load_terms:
                out[:, spec.joint] += float(theta[0]) * load_slope(spec, loaded)
            return out

        return self._remembered('load share', (r, self.load_terms, self.link_terms), share)

    def _delay_secant(
        self, r: PreparedRecording, spec: EffectSpec
    ) -> tuple[np.ndarray, np.ndarray]:
        """A delay's column about a delay d0 > 0 [N*m/s], raw and as the label meets it.

        (tau(t - d0) - tau(t)) / d0 of the torque it delays (the nominal one, plus the rate
        terms' in the whole model's form): at d = d0 the column times d is the delay's torque
        exactly, where the rate (the column about 0) leaves a d^2 / 2 tau'' error that grows
        with the delay and the label's band. The shift is taken on the torque as the label
        meets it (smooth), so that a friction step is not interpolated.
        """
        d0 = delay_about(spec)
        total = r.quantities.tau_nominal
        if whole_model_delay(spec):
            total = total + self._terms_torque(r, self.rate_terms)
        dataset = r.dataset
        both = np.stack([total, as_label(total, dataset)], axis=-1)  # raw, as the label meets it
        change = np.zeros_like(both)
        for rows in dataset.recording_rows():
            if len(rows) < 4:  # too short for a spline: inside the filter's start-up, trimmed
                continue
            change[rows] = time_shifted(both[rows], d0, dataset.period_s) - both[rows]
        return change[..., :1] / d0, change[..., 1:] / d0

    def _terms_rate(self, r: PreparedRecording) -> np.ndarray:
        """(N, n) time derivative of the rate terms' torque along one recording [N*m/s].

        A delay holds back the whole torque the drive delivers, friction included, not only
        the rigid body's (``CandidateSet.refine``).
        """
        torque = self._terms_torque(r, self.rate_terms)
        rate = np.zeros_like(torque)
        for rows in r.dataset.recording_rows():
            if len(rows) > 2:
                rate[rows] = differentiate(torque[rows], r.dataset.period_s)
        return rate

    def _terms_torque(
        self, r: PreparedRecording, terms: list[tuple[EffectSpec, np.ndarray]]
    ) -> np.ndarray:
        """(N, n) the torque of some terms along one recording [N*m] (unfiltered)."""

        def torque() -> np.ndarray:
            out = np.zeros_like(r.quantities.q)
            for spec, theta in terms:
                quantities = self._loaded(r) if uses_model_load(spec) else r.quantities
                out += effect_columns(spec, quantities, self.model) @ theta
            out.setflags(write=False)  # shared by every caller
            return out

        return self._remembered('torque', (r, terms, self.link_terms), torque)

    def _loaded(self, r: PreparedRecording) -> NominalQuantities:
        """A recording's quantities with the link torque of the nominal model plus link terms."""

        def loaded() -> NominalQuantities:
            link = r.quantities.tau_rigid.copy()
            for spec, theta in self.link_terms:
                link += effect_columns(spec, r.quantities, self.model) @ theta
            return replace(r.quantities, tau_rigid=link)

        return self._remembered('loaded', (r, self.link_terms), loaded)

    def _remembered(self, what: str, keys: tuple[object, ...], compute: Callable[[], _T]) -> _T:
        """``compute()``, kept while the term lists in ``keys`` are the problem's current ones.

        Every delay and torque-constant candidate of the whole model's form needs the same
        terms' torque along each recording, and every model-load friction the same link torque.
        ``what``: the quantity; ``keys``: the recording (or the problem), then the term lists it
        depends on.
        """
        key: tuple[str | int, ...] = (what, *(id(k) for k in keys))
        hit = self._memo.get(key)
        if hit is not None:  # its keys are held, so no other object has their ids
            return cast(_T, hit[1])
        value = compute()
        live = {
            id(t) for t in (self.link_terms, self.load_terms, self.rate_terms, self.scale_terms)
        }
        self._memo = {k: v for k, v in self._memo.items() if set(k[2:]) <= live}
        self._memo[key] = (keys, value)
        return value

    def times(self, part: str) -> np.ndarray:
        """Times [s] of one part's kept rows; later recordings follow the earlier ones."""
        out, offset = [], 0.0
        for r in self.recordings:
            t = (r.dataset.stamps_ns - r.dataset.stamps_ns[0]) * 1e-9
            out.append(t[r.rows[part]] + offset)
            offset += float(t[-1]) + self.period
        return np.concatenate(out)

    def pooled(self, design: Design) -> Design:
        """``design`` with the held-out part joined to the training part for the values' fit.

        The held-out part is projected off its own standstills, as the training part is.
        """
        return design.pooled(
            lambda x: self.standstill.project(x, 'test'), self.standstill.counts['test']
        )

    def n_effective(self, part: str) -> np.ndarray:
        """(n,) effective samples per joint on one part.

        Each standstill's free held torque takes one from the training part (``standstill``).
        """
        rows = sum(len(r.rows[part]) for r in self.recordings)
        n_eff = rows * self.step / self.noise.correlation_samples
        if part == 'train':
            n_eff = np.maximum(n_eff - self.standstill.counts['train'], 1.0)
        return n_eff
