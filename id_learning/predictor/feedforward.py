"""FeedForwardPredictor: one reference sample in, one guarded feed-forward torque tau_u out.

Guards, in the order they run (the first that fails decides; nothing is returned then):

1. joints: the sample's names must be the model's joints (any order: columns are reordered by
   name), with one value per joint in q and v (and a, when given);
2. finite: no NaN or Inf in q, v or a;
3. age (optional): not older than ``max_age_s`` against the caller's clock;
4. stamp: strictly newer than the last accepted sample;
5. range: inside the training range widened by ``range_margin``; 'fallback' blends in the
   physics prior's torque across the margin and publishes it alone beyond
   (``predictor.fallback``), 'warn' counts and predicts, 'reject' drops the sample;
6. output: a non-finite prediction is dropped; a finite one is clamped to the torque limits.

A rejected sample leaves the history untouched. A gap of more than ``stale_after_cycles``
periods between accepted samples, in stamps or in receive time, marks a stale episode. A gap in
the stamps (a hole in the trajectory) also resets the history: the acceleration estimate starts
again and the LSTM window is refilled with the first new sample, as the offline ``predict`` pads
a run. Samples that arrive late but with contiguous stamps keep the history.

Inference (``inference``): 'numpy' (default) evaluates the model's float64 numpy path
(``sample_predictor``, or the LSTM's ``sequence_predictor``), built once from the fitted weights;
it equals the torch path up to float32 rounding (relative ~1e-6) and costs a fraction of it for
one sample. 'torch' calls the model's own ``predict`` (``predict_window`` for the LSTM).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.plausibility import SampleGate
from id_learning.errors import ConfigError
from id_learning.models.base import InverseDynamicsModel
from id_learning.predictor.acceleration import CausalAccelerationEstimator
from id_learning.predictor.adaptation import AdaptationLoop
from id_learning.predictor.config import GuardConfig
from id_learning.predictor.fallback import (
    PhysicsFallback,
    blend_weight,
    is_network,
    physics_fallback,
)
from id_learning.predictor.outcome import PredictorCounters, Reject, StepResult
from id_learning.predictor.ranges import TrainingRange, training_range
from id_learning.predictor.sample import ReferenceSample
from id_learning.predictor.timing import RollingStats
from id_learning.robot.config import JointLimits, RobotConfig

__all__ = [
    'INFERENCE_BACKENDS',
    'FeedForwardPredictor',
    'PredictorCounters',
    'ReferenceSample',
    'Reject',
    'StepResult',
]

_LOG = logging.getLogger(__name__)

INFERENCE_BACKENDS = ('numpy', 'torch')
#: The column order of a sender whose joint order is the model's (no reordering).
_IDENTITY = np.arange(0)
InferenceBackend = Literal['numpy', 'torch']


class FeedForwardPredictor:
    """Guarded tau_u prediction from reference samples, one sample per call.

    Args:
        model: a fitted model; its joint_names fix the output order.
        torque_limit: (n,) the robot's symmetric torque limits [N*m]; the output is clamped to
            ``config.torque_limit_scale`` times these.
        config: guard settings.
        training_range: bounds to warn about (None: no range check).
        compute_stats: capacity of the compute-latency window.
        inference: 'numpy' (the model's float64 one-sample path) or 'torch' (its predict).
        limits: the robot's joint limits in the model's joint order: a sample no arm of them can
            be in (``dataset.plausibility.SampleGate``) gives no torque (``Reject.IMPOSSIBLE``),
            whatever the training range and ``out_of_range`` say. None: no such gate.
        fallback: the physics prior for ``out_of_range`` 'fallback' (and 'auto' on a network);
            None: 'auto' warns instead.

    Raises:
        ValueError: bad torque limits or an unknown inference backend.
        ConfigError: out_of_range 'fallback' for a network without a physics prior.
    """

    def __init__(
        self,
        model: InverseDynamicsModel,
        torque_limit: np.ndarray,
        config: GuardConfig | None = None,
        training_range: TrainingRange | None = None,
        *,
        compute_stats: int = 4096,
        inference: InferenceBackend = 'numpy',
        limits: JointLimits | None = None,
        fallback: PhysicsFallback | None = None,
    ) -> None:
        """Keep the model and prepare the per-stream state."""
        if inference not in INFERENCE_BACKENDS:
            raise ValueError(f'inference must be one of {INFERENCE_BACKENDS}, got {inference!r}')
        self.model = model
        self.fallback = fallback
        #: Online adaptation to drift (``adaptation.AdaptationLoop``); None: the model as fitted.
        self.adaptation: AdaptationLoop | None = None
        #: The torque the model predicts ('motor' tau_u or 'joint'), where the artifact says.
        self.target: str | None = None
        self.inference = inference
        self.config = config or GuardConfig()
        self.joint_names: tuple[str, ...] = tuple(model.joint_names)
        n = len(self.joint_names)
        limit = np.asarray(torque_limit, dtype=float)
        if limit.shape != (n,) or not np.all(limit > 0):
            raise ValueError(f'torque_limit must be ({n},) positive values, got {limit}')
        self._robot_limit = limit
        self._training_range = training_range
        self.torque_limit = limit * self.config.torque_limit_scale
        self.range = (
            None if training_range is None else training_range.widened(self.config.range_margin)
        )
        self.out_of_range_action = self._action(self.config)
        self.counters = PredictorCounters(n)
        self._gate = None if limits is None else SampleGate(self.joint_names, limits)
        self.compute_s = RollingStats(compute_stats)
        self._n = n
        self._index = {name: k for k, name in enumerate(self.joint_names)}
        self._orders: dict[tuple[str, ...], np.ndarray | None] = {}
        self._estimator = CausalAccelerationEstimator(self.config.acceleration_cutoff_hz)
        self.is_sequence_model = bool(getattr(model, 'is_sequence_model', False))
        self.sequence_length = int(getattr(model, 'sequence_length', 0) or 0)
        if self.is_sequence_model and self.sequence_length < 1:
            self.sequence_length = int(model.config.sequence_length)  # type: ignore[attr-defined]
        self._window: np.ndarray | None = None
        # Built once: exporting weights per sample would cost more than the prediction.
        self._sequence = (
            model.sequence_predictor()  # type: ignore[attr-defined]
            if self.is_sequence_model and inference == 'numpy'
            else None
        )
        self._predict_one: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] = (
            model.sample_predictor()
            if inference == 'numpy' and not self.is_sequence_model
            else self._predict_torch
        )
        self._last_stamp_ns: int | None = None
        self._last_receive_ns: int | None = None
        self._is_stale = False
        #: The artifact's input definitions (``from_artifact``): what the model is served on and
        #: what it was fitted on; None where unknown.
        self.inputs: InputDefinition | None = None
        self.fitting_inputs: InputDefinition | None = None

    def _action(self, config: GuardConfig) -> str:
        """The out-of-range action ``config`` asks for, 'auto' resolved."""
        action = config.out_of_range
        if action in ('auto', 'fallback') and not is_network(self.model):
            return 'warn'  # a physics model is its own prior: there is nothing to fall back to
        if action == 'auto':
            return 'fallback' if self.fallback is not None else 'warn'
        if action == 'fallback' and self.fallback is None:
            raise ConfigError("out_of_range 'fallback' needs a physics prior (fallback=...)")
        return action

    # -- construction -----------------------------------------------------------------------------
    @classmethod
    def from_artifact(
        cls,
        folder: Path | str,
        robot: RobotConfig,
        config: GuardConfig | None = None,
        *,
        inference: InferenceBackend = 'numpy',
        fallback_artifact: Path | str | None = None,
    ) -> FeedForwardPredictor:
        """Load an artifact of any model kind for a robot and guard it with its training range.

        Args:
            fallback_artifact: a physics artifact to fall back to outside the training range;
                None: the run's rnea_id beside the model, else the model's own physics part,
                else the nominal model (``predictor.fallback``).

        Raises:
            CheckpointError: the artifact (or the fallback artifact) is invalid, belongs to
                another robot, or the fallback is no physics model of the same target.
        """
        from id_learning.models.artifact import METADATA_FILE, artifact_inputs, artifact_target
        from id_learning.models.registry import load_model

        config = config or GuardConfig(period_s=robot.ipo_period_s)
        model = load_model(Path(folder), robot)
        metadata = json.loads((Path(folder) / METADATA_FILE).read_text(encoding='utf-8'))
        predictor = cls(
            model,
            robot.limits.torque,
            config,
            training_range(model.fitted_metadata(), robot),
            inference=inference,
            limits=robot.limits.take([robot.joints.index(name) for name in model.joint_names]),
            fallback=physics_fallback(
                model, robot, artifact_target(metadata), fallback_artifact, beside=folder
            )
            if is_network(model)
            else None,
        )
        predictor.inputs, predictor.fitting_inputs = artifact_inputs(metadata)
        predictor.target = artifact_target(metadata)
        return predictor

    def warm_up(self, calls: int = 25) -> None:
        """Run the guards and the model on a sample at rest, leaving no trace in the state.

        The first calls of a path pay one-off costs (buffers, caches, lazy set-up): measured
        here, a first step takes about twice as long as the next ones without this.
        """
        if self.range is not None and 'q' in self.range.bounds:
            low, high = self.range.bounds['q']
            q = 0.5 * (low + high)
        else:
            q = np.zeros(self._n)
        zeros = np.zeros(self._n)
        trained, fallback = self._training_range, self.fallback
        for _ in range(calls):
            if self.range is not None:
                self.range.first_violation(q, zeros, zeros)
            if trained is not None:
                trained.excess(q, zeros, zeros)
            if fallback is not None:
                fallback.predict_one(q, zeros, zeros)
            self._predict(q, zeros, zeros)
        self._window = None
        if self._sequence is not None:
            self._sequence.reset()

    def update_config(self, config: GuardConfig) -> None:
        """Apply new guard settings to the running stream (limits, margins, age, cut-off).

        The history is kept; a new acceleration cut-off applies from the next sample.
        """
        self.out_of_range_action = self._action(config)
        self.config = config
        self.torque_limit = self._robot_limit * config.torque_limit_scale
        self.range = (
            None
            if self._training_range is None
            else self._training_range.widened(config.range_margin)
        )
        self._estimator.cutoff_hz = config.acceleration_cutoff_hz

    # -- state ------------------------------------------------------------------------------------
    @property
    def is_stale(self) -> bool:
        """The reference is stale: no valid sample for more than the threshold."""
        return self._is_stale

    def reset(self) -> None:
        """Forget the history (acceleration estimate, LSTM window, last stamp)."""
        self._estimator.reset()
        self._window = None
        if self._sequence is not None:
            self._sequence.reset()
        self._last_stamp_ns = None
        self.counters.history_resets += 1

    def check_stale(self, now_ns: int) -> bool:
        """Update the stale flag at time ``now_ns`` (same clock as step's receive_ns).

        Returns:
            True when the reference has just become stale (once per episode).
        """
        last = self._last_receive_ns
        if self._is_stale or last is None or now_ns - last <= self.config.stale_after_ns:
            return False
        self._is_stale = True
        self.counters.stale_episodes += 1
        return True

    def silence_ns(self, now_ns: int) -> int | None:
        """Time since the last accepted sample [ns], or None before the first one."""
        return None if self._last_receive_ns is None else now_ns - self._last_receive_ns

    # -- the step ---------------------------------------------------------------------------------
    def _order(self, names: tuple[str, ...]) -> np.ndarray | None:
        order = self._orders.get(names)
        if order is None and names not in self._orders:
            if names == self.joint_names:
                order = _IDENTITY
            elif len(names) == self._n and set(names) == set(self.joint_names):
                order = np.array([names.index(name) for name in self.joint_names])
            if len(self._orders) < 64:  # a bounded cache: a bad sender cannot grow it forever
                self._orders[names] = order
        return order

    def _reject(self, sample: ReferenceSample, reason: Reject, detail: str) -> StepResult:
        self.counters.rejects[reason] += 1
        return StepResult(sample.stamp_ns, None, reason, detail)

    def _validate(
        self, sample: ReferenceSample, clock_ns: int | None
    ) -> tuple[np.ndarray, ...] | StepResult:
        names = tuple(sample.names)
        if len(names) != self._n:
            return self._reject(
                sample,
                Reject.JOINT_COUNT,
                f'{len(names)} joints {list(names)}, the model has {self._n}: '
                f'{list(self.joint_names)}',
            )
        order = self._order(names)
        if order is None:
            missing = [name for name in self.joint_names if name not in names]
            extra = [name for name in names if name not in self._index]
            return self._reject(
                sample,
                Reject.JOINT_NAMES,
                f'joint names {list(names)} do not match the model '
                f'{list(self.joint_names)} (missing {missing}, unexpected {extra})',
            )
        arrays = [sample.q, sample.v] + ([] if sample.a is None else [sample.a])
        for label, values in zip(('q', 'v', 'a'), arrays, strict=False):
            if np.shape(values) != (self._n,):
                return self._reject(
                    sample,
                    Reject.SHAPE,
                    f'{label} has {np.size(values)} values for {self._n} joints',
                )
        if order is _IDENTITY:  # the sender's order is the model's: no copy needed
            q, v = np.asarray(sample.q, float), np.asarray(sample.v, float)
            a = None if sample.a is None else np.asarray(sample.a, float)
        else:
            q, v = np.asarray(sample.q, float)[order], np.asarray(sample.v, float)[order]
            a = None if sample.a is None else np.asarray(sample.a, float)[order]
        # One test of all values first (a sum is finite only if every term is); the
        # per-quantity search runs only when it fails.
        total = np.add.reduce(q) + np.add.reduce(v) + (0.0 if a is None else np.add.reduce(a))
        if not math.isfinite(total):
            checks: tuple[tuple[str, np.ndarray | None], ...] = (('q', q), ('v', v), ('a', a))
            for label, checked in checks:
                if checked is not None and not np.isfinite(checked).all():
                    j = int(np.argmax(~np.isfinite(checked)))
                    return self._reject(
                        sample,
                        Reject.NON_FINITE,
                        f'{label} of {self.joint_names[j]} is {checked[j]}',
                    )
        if self.config.max_age_s > 0 and clock_ns is not None:
            age_ns = clock_ns - sample.stamp_ns
            if age_ns > self.config.max_age_s * 1e9:
                return self._reject(
                    sample,
                    Reject.TOO_OLD,
                    f'stamp is {age_ns * 1e-6:.1f} ms old (max_age_s {self.config.max_age_s:g} s)',
                )
        if self._last_stamp_ns is not None and sample.stamp_ns <= self._last_stamp_ns:
            return self._reject(
                sample,
                Reject.STAMP_ORDER,
                f'stamp {sample.stamp_ns} ns is not after the last accepted '
                f'{self._last_stamp_ns} ns',
            )
        if self._gate is not None:
            violation = self._gate.violation(q, v, a)
            if violation is not None:
                return self._reject(sample, Reject.IMPOSSIBLE, violation)
        return (q, v) if a is None else (q, v, a)

    def step(
        self, sample: ReferenceSample, receive_ns: int, clock_ns: int | None = None
    ) -> StepResult:
        """Guard one sample and predict its torque.

        Args:
            sample: the reference sample as received.
            receive_ns: when it arrived, on a monotonic clock [ns] (stale detection).
            clock_ns: the current time in the stamps' time base [ns], for the age check; None
                skips it.

        Returns:
            The torque in the model's joint order, or the reason there is none.
        """
        counters = self.counters
        counters.received += 1
        checked = self._validate(sample, clock_ns)
        if isinstance(checked, StepResult):
            return checked
        config = self.config
        stale_after_ns = config.stale_after_ns

        # Silence in arrival ends a stale episode; only a hole in the stamps breaks the
        # trajectory, so only that resets the history (late but contiguous samples keep it).
        stamp_gap = (
            self._last_stamp_ns is not None
            and sample.stamp_ns - self._last_stamp_ns > stale_after_ns
        )
        receive_gap = (
            self._last_receive_ns is not None
            and receive_ns - self._last_receive_ns > stale_after_ns
        )
        if (stamp_gap or receive_gap) and not self._is_stale:
            counters.stale_episodes += 1
        resumed = self._is_stale or stamp_gap or receive_gap
        if stamp_gap:
            self.reset()
        elif self._last_stamp_ns is not None:
            step = (sample.stamp_ns - self._last_stamp_ns) * 1e-9 / config.period_s
            counters.skipped_cycles += max(round(step) - 1, 0)
        self._is_stale = False
        self._last_stamp_ns = sample.stamp_ns
        self._last_receive_ns = receive_ns

        start = time.perf_counter()
        q, v = checked[0], checked[1]
        a = checked[2] if len(checked) == 3 else self._estimator.update(sample.stamp_ns, v)
        if self.out_of_range_action == 'fallback':
            tau, share, detail = self._predict_or_fall_back(q, v, a)
            out_of_range = share >= 1.0
        else:
            share = 0.0
            out_of_range = False
            detail = None
            if self.range is not None:
                violation = self.range.first_violation(q, v, a)
                if violation is not None:
                    out_of_range = True
                    counters.out_of_range += 1
                    detail = f'{violation.describe()} ({self.range.source})'
            if out_of_range and self.out_of_range_action == 'reject':
                self._push_window(q, v, a)  # the motion happened: keep the history continuous
                return self._reject(sample, Reject.OUT_OF_RANGE, detail or '')
            tau = self._predict(q, v, a)
        if self.adaptation is not None:  # the drift the model lacks, learnt from the currents
            # Not learnt from while the physics prior serves: its torque is another model's.
            tau = self.adaptation.serve(sample.stamp_ns, (q, v, a), tau, learn=share == 0.0)
        self.compute_s.add(time.perf_counter() - start)
        if not np.isfinite(tau).all():
            return self._reject(
                sample, Reject.NON_FINITE_OUTPUT, f'model returned non-finite torque {tau}'
            )
        over = np.abs(tau) > self.torque_limit
        is_clamped = bool(over.any())
        if is_clamped:
            tau = np.clip(tau, -self.torque_limit, self.torque_limit)
            counters.clamped_samples += 1
            counters.clamped_per_joint += over
        counters.predicted += 1
        return StepResult(
            sample.stamp_ns,
            tau,
            detail=detail,
            is_clamped=is_clamped,
            is_out_of_range=out_of_range,
            resumed_after_stale=resumed,
            physics_share=share,
        )

    def _predict_or_fall_back(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray
    ) -> tuple[np.ndarray, float, str | None]:
        """(tau, physics share, detail) under out_of_range 'fallback'.

        The network's torque inside the training range, the physics prior's beyond its margin,
        blended between.
        """
        assert self.fallback is not None
        trained = self._training_range
        excess = 0.0 if trained is None else trained.excess(q, v, a)
        share = blend_weight(excess, self.config.range_margin)
        if share <= 0.0:
            return self._predict(q, v, a), 0.0, None
        assert trained is not None
        counters = self.counters
        counters.fallback_samples += 1
        violation = trained.first_violation(q, v, a)
        detail = (
            f'{violation.describe() if violation else "outside"} ({trained.source}): '
            f'physics share {share:.2f} ({self.fallback.source})'
        )
        physics = self.fallback.predict_one(q, v, a)
        if share >= 1.0:
            counters.out_of_range += 1
            self._push_window(q, v, a)  # the motion happened: keep the history continuous
            return physics, 1.0, detail
        network = self._predict(q, v, a)
        if not np.isfinite(network).all():  # the prior is the safe answer here too
            return physics, share, detail
        return (1.0 - share) * network + share * physics, share, detail

    def prepare_next(self) -> None:
        """Do ahead of the next sample what depends on the past alone (after a publish).

        The LSTM's recurrent products of every window in flight; nothing for other models. The
        next ``step`` does it itself when this was not called, with the same result.
        """
        if self._sequence is not None:
            self._sequence.prepare()

    def _push_window(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray | None:
        """Append a sample to the sequence model's history; the numpy path returns its torque."""
        if not self.is_sequence_model:
            return None
        row = np.concatenate([q, v, a])
        if self._sequence is not None:
            tau: np.ndarray = self._sequence.push(row)
            return tau
        if self._window is None:
            # As the offline predict pads a run: the first sample repeated over the window.
            self._window = np.repeat(row[None], self.sequence_length, axis=0)
        else:
            self._window[:-1] = self._window[1:]
            self._window[-1] = row
        return None

    def _predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        if self.is_sequence_model:
            tau = self._push_window(q, v, a)
            if tau is not None:
                return tau
            with torch.inference_mode():
                return np.asarray(self.model.predict_window(self._window), dtype=float)  # type: ignore[attr-defined]
        return self._predict_one(q, v, a)

    def _predict_torch(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            return np.asarray(self.model.predict(q[None], v[None], a[None]), dtype=float)[0]
