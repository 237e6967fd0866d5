"""FeedForwardPredictor: one reference sample in, one guarded feed-forward torque tau_u out.

Guards, in the order they run (the first that fails decides):

1. joints, shapes, finite values (``predictor.guards``);
2. time (``predictor.stamps``): the stamp after the last accepted one, at most ``max_age_s`` late
   and one IPO period ahead against the stream's time base; ``resync_after`` such rejections in a
   row start a new time base (one warning; the only place published stamps may step back);
3. plausible: a state an arm of these limits can be in (``dataset.plausibility.SampleGate``);
4. consistent: the sample follows from the ones before it, its given accelerations integrate to
   the velocities' change (``predictor.acceleration_gate``), and the last 2 s of velocities
   integrate to the positions' change (``dataset.consistency``); one that does not yields no
   model torque, nor do the ``rearm_samples`` consistent ones after it (or after a new time
   base): they get the hold output instead;
5. range: inside the training range widened by ``range_margin``; 'fallback' blends in the
   physics prior's torque across the margin and publishes it alone beyond
   (``predictor.fallback``), 'warn' counts and predicts, 'reject' drops the sample;
6. output (``predictor.output``): a non-finite prediction is dropped; a finite one is clamped to
   the torque limits and slew-limited. The hold output is the last published torque slewed
   towards the physics prior's torque at rest at the last pose served, while the reference is
   not stale.

A refused sample (1-3) leaves the history untouched. A gap of more than ``stale_after_cycles``
periods between accepted samples, in stamps or in receive time, marks a stale episode; a gap in
the stamps (a hole) also resets the history (acceleration estimate, LSTM window refilled with the
first new sample, as the offline ``predict`` pads a run). After any bad sample a valid stream is
served again from its ``recovery_samples``-th sample at the latest; after velocities scaled
against their positions, from its ``scale_recovery_samples``-th.

Inference (``inference``): 'numpy' (default) evaluates the model's float64 numpy path
(``sample_predictor``, or the LSTM's ``sequence_predictor``), built once from the fitted weights;
it equals the torch path up to float32 rounding (relative ~1e-6) and costs a fraction of it for
one sample. 'torch' calls the model's own ``predict`` (``predict_window`` for the LSTM).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from id_learning.dataset.consistency import KinematicConsistency
from id_learning.dataset.inputs import InputDefinition
from id_learning.dataset.plausibility import SampleGate
from id_learning.errors import ConfigError
from id_learning.models.base import InverseDynamicsModel, as_sequence_model
from id_learning.predictor.acceleration import CausalAccelerationEstimator
from id_learning.predictor.acceleration_gate import StreamGate
from id_learning.predictor.adaptation import AdaptationLoop
from id_learning.predictor.config import GuardConfig
from id_learning.predictor.fallback import (
    PhysicsFallback,
    blend_weight,
    is_network,
    physics_fallback,
)
from id_learning.predictor.guards import Checked, SampleCheck
from id_learning.predictor.outcome import PredictorCounters, Reject, StepResult
from id_learning.predictor.output import OutputStage
from id_learning.predictor.ranges import TrainingRange, training_range
from id_learning.predictor.sample import ReferenceSample
from id_learning.predictor.stamps import StampClock
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


INFERENCE_BACKENDS = ('numpy', 'torch')
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
            whatever the training range and ``out_of_range`` say, and one that does not follow
            from the samples before it (``dataset.consistency``) gives no model torque. None:
            neither gate.
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
        self.model = model.for_the_drive()
        self.fallback = fallback
        #: Online adaptation to drift (``adaptation.AdaptationLoop``); None: the model as fitted.
        self.adaptation: AdaptationLoop | None = None
        #: The torque the model predicts ('motor' tau_u or 'joint'), where the artifact says.
        self.target: str | None = None
        self.inference = inference
        self.config = config = config or GuardConfig()
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
        self._limits = limits
        gate = self._consistency_gate(self.config)
        self._consistency = None if gate is None else StreamGate(gate)
        self._check = SampleCheck(self.joint_names)
        self._clock = StampClock(config.max_age_s, config.resync_after, config.period_s)
        self.output = OutputStage(*self._output_settings(self.config))
        #: Consistent samples since the last inconsistent one, up to rearm_samples (armed at
        #: start and after a hole: there is nothing to doubt the stream yet).
        self._armed = self.config.rearm_samples
        self._served_q: np.ndarray | None = None
        self._served_receive_ns: int | None = None
        self._hold_target: np.ndarray | None = None
        self.compute_s = RollingStats(compute_stats)
        self._n = n
        self._estimator = CausalAccelerationEstimator(self.config.acceleration_cutoff_hz)
        self._sequence_model = as_sequence_model(model)
        self.is_sequence_model = self._sequence_model is not None
        self.sequence_length: int = getattr(self._sequence_model, 'sequence_length', 0)
        self._window: np.ndarray | None = None
        # Built once: exporting weights per sample would cost more than the prediction.
        self._sequence = (
            self._sequence_model.sequence_predictor()
            if self._sequence_model is not None and inference == 'numpy'
            else None
        )
        self._predict_one: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] = (
            model.sample_predictor()
            if inference == 'numpy' and not self.is_sequence_model
            else self._predict_torch
        )
        self._last_receive_ns: int | None = None
        self._is_stale = False
        #: The artifact's input definitions (``from_artifact``): what the model is served on and
        #: what it was fitted on; None where unknown.
        self.inputs: InputDefinition | None = None
        self.fitting_inputs: InputDefinition | None = None

    def _consistency_gate(self, config: GuardConfig) -> KinematicConsistency | None:
        if self._limits is None:
            return None
        scale = config.consistency_scale
        return KinematicConsistency(self.joint_names, self._limits, config.period_s, scale)

    def _output_settings(self, config: GuardConfig) -> tuple[np.ndarray, np.ndarray, float, float]:
        slew = self._robot_limit / config.torque_rise_s
        return self.torque_limit, slew, config.period_s, config.stale_after_ns * 1e-9

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
        from id_learning.models import artifact
        from id_learning.models.registry import load_model

        config = config or GuardConfig(
            period_s=robot.ipo_period_s, consistency_scale=robot.consistency_scale
        )
        model = load_model(Path(folder), robot).for_the_drive()
        metadata = artifact.read_metadata(Path(folder) / artifact.METADATA_FILE)
        predictor = cls(
            model,
            robot.limits.torque,
            config,
            training_range(model.fitted_metadata(), robot),
            inference=inference,
            limits=robot.limits.take([robot.joints.index(name) for name in model.joint_names]),
            fallback=physics_fallback(
                model, robot, artifact.artifact_target(metadata), fallback_artifact, beside=folder
            )
            if is_network(model)
            else None,
        )
        predictor.inputs, predictor.fitting_inputs = artifact.artifact_inputs(metadata)
        predictor.target = artifact.artifact_target(metadata)
        return predictor

    @property
    def skipped_in_holes(self) -> int:
        """IPO cycles the stamps skipped in gaps longer than the stale threshold (``stamps``)."""
        return self._clock.hole_cycles

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

        The history is kept, the consistency gate's too (``regate``); the output continues from
        the last torque, a lower limit holding at once; a new cut-off applies from the next sample.
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
        self._clock.configure(config.max_age_s, config.resync_after, config.period_s)
        self.output.configure(*self._output_settings(config))
        gate = self._consistency_gate(config)
        if self._consistency is not None and gate is not None:
            self._consistency.regate(gate)

    @property
    def recovery_samples(self) -> int:
        """After any bad sample, a valid stream is served again from at most its this-many-th."""
        window = 0 if self._consistency is None else self._consistency.gate.window
        return self.config.resync_after + window + self.config.rearm_samples + 1

    @property
    def scale_recovery_samples(self) -> int:
        """The same after velocities scaled against their positions (``ConsistencyStream``)."""
        stream = self._consistency
        scaled = 0 if stream is None else stream.recovery_samples + self.config.rearm_samples + 1
        return max(self.recovery_samples, scaled)

    @property
    def is_stale(self) -> bool:
        """The reference is stale: no valid sample for more than the threshold."""
        return self._is_stale

    def reset(self) -> None:
        """Forget the history (acceleration estimate, LSTM window, consistency, last stamp)."""
        self._forget_motion()
        if self._consistency is not None:
            self._consistency.reset()
        self._clock.last_stamp_ns = None
        self.counters.history_resets += 1

    def _forget_motion(self) -> None:
        """The acceleration estimate and the LSTM window start again."""
        self._estimator.reset()
        self._window = None
        if self._sequence is not None:
            self._sequence.reset()

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
    def _reject(self, sample: ReferenceSample, reason: Reject, detail: str) -> StepResult:
        self.counters.rejects[reason] += 1
        return StepResult(sample.stamp_ns, None, reason, detail)

    def step(
        self, sample: ReferenceSample, receive_ns: int, clock_ns: int | None = None
    ) -> StepResult:
        """Guard one sample and predict its torque.

        Args:
            sample: the reference sample as received.
            receive_ns: when it arrived, on a monotonic clock [ns] (stale detection, and the
                time base's clock when ``clock_ns`` is None).
            clock_ns: the current time on another clock for the time base [ns] (the ROS clock,
                e.g. a replay's /clock); None: ``receive_ns``.

        Returns:
            The torque to publish in the model's joint order, or the reason there is none.
        """
        counters = self.counters
        counters.received += 1
        checked = self._check(sample)
        if isinstance(checked[0], Reject):
            return self._reject(sample, checked[0], str(checked[1]))
        q, v, given_a = checked
        config, clock = self.config, self._clock
        counters.skipped_cycles += clock.skipped(
            sample.stamp_ns, config.stale_after_ns, config.period_s
        )
        now_ns = receive_ns if clock_ns is None else clock_ns
        refused = clock.judge(sample.stamp_ns, now_ns)
        if refused is not None and not clock.should_resync():
            return self._reject(sample, *refused)
        if self._gate is not None:
            violation = self._gate.violation(q, v, given_a)
            if violation is not None:
                if refused is None:  # a stamp of the stream: the time base follows it (a backlog)
                    clock.accept(sample.stamp_ns, now_ns)
                return self._reject(sample, Reject.IMPOSSIBLE, violation)
        if refused is None:
            return self._taken(sample, receive_ns, (q, v, given_a), now_ns)
        self.reset()  # resynchronised: a new time base, and what the old one refused is said
        clock.resync(sample.stamp_ns, now_ns)
        counters.resyncs += 1
        self._armed = 0  # nothing to compare the first sample of a new time base with
        result = self._taken(sample, receive_ns, (q, v, given_a), now_ns)
        return replace(result, resynced=True, detail=f'{refused[1]}; {result.detail or "served"}')

    def _taken(
        self, sample: ReferenceSample, receive_ns: int, checked: Checked, now_ns: int
    ) -> StepResult:
        """The rest of the step for a sample the time base takes: consistency, model, output."""
        q, v, given_a = checked
        resumed = self._follow(sample.stamp_ns, receive_ns, now_ns)
        stream = self._consistency
        if stream is not None:
            inconsistency = stream.check(sample.stamp_ns, q, v, given_a)
            stream.push(sample.stamp_ns, q, v, given_a)
            if inconsistency is not None:
                self._armed = 0
                self._forget_motion()
                return self._held(
                    sample, receive_ns, Reject.INCONSISTENT, inconsistency.describe()
                )
        a = given_a if given_a is not None else self._estimator.update(sample.stamp_ns, v)
        if stream is not None and self._armed < self.config.rearm_samples:
            self._armed += 1
            self._push_window(q, v, a)  # the motion happened: keep the history continuous
            return self._held(sample, receive_ns, Reject.REARMING,
                              f'consistent sample {self._armed} of {self.config.rearm_samples} '
                              'before the model serves again')  # fmt: skip
        return self._serve(sample, receive_ns, (q, v, a), resumed=resumed)

    def _follow(self, stamp_ns: int, receive_ns: int, now_ns: int) -> bool:
        """Take an accepted sample into the time base; whether it ends a stale episode.

        Silence in arrival ends a stale episode; only a hole in the stamps breaks the
        trajectory, so only that resets the history (late but contiguous samples keep it).
        """
        counters = self.counters
        stale_after_ns = self.config.stale_after_ns
        last_stamp = self._clock.last_stamp_ns
        stamp_gap = last_stamp is not None and stamp_ns - last_stamp > stale_after_ns
        receive_gap = (
            self._last_receive_ns is not None
            and receive_ns - self._last_receive_ns > stale_after_ns
        )
        if (stamp_gap or receive_gap) and not self._is_stale:
            counters.stale_episodes += 1
        resumed = self._is_stale or stamp_gap or receive_gap
        if stamp_gap:
            self.reset()
        self._is_stale = False
        self._clock.accept(stamp_ns, now_ns)
        self._last_receive_ns = receive_ns
        return resumed

    def _held(
        self, sample: ReferenceSample, receive_ns: int, reason: Reject, detail: str
    ) -> StepResult:
        """No model torque: the hold output while the last served sample is recent enough."""
        self.counters.rejects[reason] += 1
        served = self._served_receive_ns
        tau = None
        if served is not None and receive_ns - served <= self.config.stale_after_ns:
            if self._hold_target is None and self._served_q is not None:
                self._hold_target = self._rest_torque(self._served_q)
            tau = self.output.hold(self._hold_target, sample.stamp_ns)
        if tau is not None:
            self.counters.held_samples += 1
        return StepResult(sample.stamp_ns, tau, reason, detail, is_held=tau is not None)

    def _rest_torque(self, q: np.ndarray) -> np.ndarray | None:
        """The physics prior's torque at rest at ``q`` (None where there is none to ask)."""
        zeros = np.zeros(self._n)
        if self.fallback is not None:
            tau = self.fallback.predict_one(q, zeros, zeros)
        elif not self.is_sequence_model:
            tau = self._predict_one(q, zeros, zeros)
        else:
            return None
        return tau if np.isfinite(tau).all() else None

    def _serve(
        self,
        sample: ReferenceSample,
        receive_ns: int,
        state: tuple[np.ndarray, np.ndarray, np.ndarray],
        *,
        resumed: bool,
    ) -> StepResult:
        """The model's torque for a sample that passed every gate, clamped and slew-limited."""
        counters = self.counters
        q, v, a = state
        start = time.perf_counter()
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
        tau, over, slewed = self.output.serve(tau, sample.stamp_ns)
        is_clamped, is_slewed = counters.count_output(over, slewed)
        counters.predicted += 1
        self._served_q, self._served_receive_ns, self._hold_target = q, receive_ns, None
        return StepResult(
            sample.stamp_ns,
            tau,
            detail=detail,
            is_clamped=is_clamped,
            is_slew_limited=is_slewed,
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
        if self._sequence_model is not None:
            tau = self._push_window(q, v, a)
            if tau is not None:
                return tau
            assert self._window is not None  # _push_window has filled it
            with torch.inference_mode():
                return np.asarray(self._sequence_model.predict_window(self._window), dtype=float)
        return self._predict_one(q, v, a)

    def _predict_torch(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            out: np.ndarray = np.asarray(
                self.model.predict(q[None], v[None], a[None]), dtype=float
            )[0]
            return out
