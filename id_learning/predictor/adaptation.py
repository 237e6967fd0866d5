"""Online adaptation of the feed-forward to a drifting machine: recursive least squares.

Friction falls as a drive warms up over a shift, so a model fitted cold drifts off. Here the
model's tau_u is corrected by the linear-in-parameters part that drifts, per joint:

    tau_u = model(q, v, a) + theta_j . [tanh(v_j / v_eps), v_j, 1]

(a Coulomb level, a viscous coefficient and an offset), with theta_j estimated from the measured
tau_u (motor currents) by recursive least squares with exponential forgetting. Safeguards, as an
adaptation inside a control loop needs them:

- outlier gating: a sample whose prediction error is beyond ``gate_sigmas`` times the running
  error scale is not learnt from (a collision, a current spike);
- bounded parameters: the correction applied uses theta clipped to ``bounds`` (a correction
  larger than a share of the torque limits is no drift); the recursion itself runs unclipped,
  since clipping its state would leave the covariance describing an estimate it no longer has
  (a robot starting from rest, where the Coulomb and viscous columns are nearly parallel, would
  then stay biased for the whole shift);
- bounded covariance: each parameter's variance is capped at its prior one, so that
  forgetting without excitation (a robot standing still) cannot wind it up;
- bounded recursion: the estimate itself stays within ``ESTIMATE_PRIOR_STDS`` prior standard
  deviations (ten times the bounds with the default prior), and the error scale within the torque
  limit: beyond, the recursion winds up on input no drift explains. A stored state beyond these
  limits is refused at load (``adaptation_store``): what a session stores, the next continues;
- frozen input: a non-finite sample, or one the caller marks stale, changes nothing; the loop
  keeps why (``frozen_reason``), and each kind of reason once for its caller to say.

The adapter is plain numpy (no ROS): the predictor node updates it from measured currents and
adds ``correction`` to every prediction. Across sessions the learnt values are kept in
``<artifact>.adaptation.json`` (``adaptation_store``): continued from at start, written back
only by a session that learnt.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.errors import ConfigError
from id_learning.models.artifact import ARTIFACT_HASH
from id_learning.physics.friction import coulomb
from id_learning.predictor.adaptation_inertia import InertiaAdapter, stabilised
from id_learning.predictor.adaptation_pairing import (
    MEASURED_CAPACITY,
    PREDICTION_CAPACITY,
    StampPairing,
)
from id_learning.predictor.adaptation_store import (
    ADAPTATION_JSON,
    COLUMNS,
    ESTIMATE_PRIOR_STDS,
    StoredBase,
    adaptation_path,
    load_base,
    model_identity,
    save_state,
    unlearnt_line,
    unloaded_base,
)
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import torque_per_ampere

__all__ = ['ADAPTATION_JSON', 'AdaptationConfig', 'AdaptationLoop', 'FrictionAdapter']

#: The corrections are bounded to this share of the torque limits: a drift, not a new model.
BOUND_SHARE = 0.1
#: The rigid body's correction may reach this share: a payload can weigh as much as a link.
INERTIA_BOUND_SHARE = 0.5
#: The adaptation's memory spans at least this many update periods.
MIN_MEMORY_PERIODS = 10
#: Currents expired unpaired in a row before the loop says that pairing keeps failing: 0.4 s at
#: the 8 ms IPO period, far beyond a few lost messages.
UNPAIRED_WARN_AFTER = 50

#: What a served prediction leaves for its currents: (v, the rigid body's regressor or None, the
#: model's tau_u); None for a cycle the physics prior served (nothing to learn from).
_Served = tuple[np.ndarray, np.ndarray | None, np.ndarray] | None
#: What a currents message leaves for its prediction: (tau_u [N*m], whether the reference was
#: stale, the joint names, the topic).
_Measured = tuple[np.ndarray, bool, tuple[str, ...], str]


@dataclass(frozen=True)
class AdaptationConfig:
    """Settings of the friction adapter.

    Attributes:
        time_constant_s: memory of the forgetting factor [s]: lambda = 1 - period / time_constant.
        smoothing_velocity: v_eps of the Coulomb column's tanh [rad/s].
        gate_sigmas: samples whose error exceeds this many running error scales are skipped.
        initial_std: prior standard deviation of each parameter (Coulomb [N*m], viscous
            [N*m*s/rad], offset [N*m]) as a share of its bound: a small prior keeps the first
            samples (a robot starting from rest, where the Coulomb and viscous columns are
            nearly parallel) from throwing the estimate about.
        max_variance: cap on each parameter's variance, as a multiple of its prior one.
    """

    time_constant_s: float = 60.0
    smoothing_velocity: float = 0.01
    gate_sigmas: float = 6.0
    initial_std: float = 0.1
    max_variance: float = 1.0


@dataclass
class _Counters:
    updates: int = 0
    gated: int = 0
    frozen: int = 0
    resets: int = 0


@dataclass
class FrictionAdapter:
    """Per-joint RLS on a Coulomb level, a viscous coefficient and an offset.

    Args:
        torque_limit: (n,) the robot's torque limits [N*m]: they scale the priors and bound
            the parameters (``BOUND_SHARE`` of the limit for Coulomb and offset, of the limit
            over ``max_velocity`` for viscous).
        max_velocity: (n,) the robot's velocity limits [rad/s].
        period_s: the update period [s] (the IPO period).
        config: the adapter's settings.
    """

    torque_limit: np.ndarray
    max_velocity: np.ndarray
    period_s: float
    config: AdaptationConfig = field(default_factory=AdaptationConfig)

    def __post_init__(self) -> None:
        """Start at theta = 0 with the prior covariance.

        Raises:
            ConfigError: a time constant shorter than ``MIN_MEMORY_PERIODS`` update periods.
        """
        if not self.config.time_constant_s >= MIN_MEMORY_PERIODS * self.period_s:
            raise ConfigError(
                f'adaptation time constant {self.config.time_constant_s:g} s: it must span at '
                f'least {MIN_MEMORY_PERIODS} periods of {self.period_s * 1e3:g} ms'
            )
        n = len(self.torque_limit)
        limit = np.asarray(self.torque_limit, dtype=float)
        share = BOUND_SHARE * limit
        self.bounds = np.stack([share, share / np.asarray(self.max_velocity), share], axis=1)
        self.theta = np.zeros((n, 3))  # what is applied: the estimate within the bounds
        self._estimate = np.zeros((n, 3))  # the recursion's own, unclipped
        self._p0 = np.stack([np.diag((self.config.initial_std * b) ** 2) for b in self.bounds])
        #: How far the recursion's estimate may go (n, 3), and the error scale (n,).
        self.estimate_limit = ESTIMATE_PRIOR_STDS * self.config.initial_std * self.bounds
        self.error_scale_limit = limit
        self.covariance = self._p0.copy()
        self.forgetting = 1.0 - self.period_s / self.config.time_constant_s
        self.error_scale = 0.02 * limit  # running RMS of the prediction error [N*m]
        self.counters = _Counters()

    def regressors(self, v: np.ndarray) -> np.ndarray:
        """(n, 3) columns of each joint at velocities v (n,)."""
        phi = np.ones((len(v), 3))
        phi[:, 0] = coulomb(v, self.config.smoothing_velocity)
        phi[:, 1] = v
        return phi

    def correction(self, v: np.ndarray) -> np.ndarray:
        """(n,) tau_u to add to the model's prediction at velocities v (n,) [N*m]."""
        theta = self.theta
        scaled = coulomb(v, self.config.smoothing_velocity)
        return scaled * theta[:, 0] + v * theta[:, 1] + theta[:, 2]

    def update(
        self,
        v: np.ndarray,
        tau_measured: np.ndarray,
        tau_model: np.ndarray,
        *,
        stale: bool = False,
    ) -> bool:
        """Learn from one sample: measured tau_u against the model's (before correction).

        Args:
            v: (n,) joint velocities [rad/s] of the sample.
            tau_measured: (n,) tau_u from the measured currents [N*m].
            tau_model: (n,) the model's tau_u at the sample, without the correction [N*m].
            stale: the inputs are not current (the caller's watchdog): nothing is learnt.

        Returns:
            Whether any joint learnt from the sample.
        """
        if stale or not np.isfinite(v.sum() + tau_measured.sum() + tau_model.sum()):
            self.counters.frozen += 1
            return False
        phi = self.regressors(v)
        error = tau_measured - tau_model - (phi * self._estimate).sum(axis=1)
        lam = self.forgetting
        limit = self.config.gate_sigmas * self.error_scale
        accept = np.abs(error) <= limit
        # The error scale learns from every sample, gated ones with their error clipped to the
        # gate: a scale that had shrunk to the noise of a standstill grows back within a second
        # of motion, instead of gating every sample from then on.
        clipped = np.minimum(np.abs(error), limit)
        self.error_scale = np.minimum(
            np.sqrt(lam * self.error_scale**2 + (1 - lam) * clipped**2), self.error_scale_limit
        )
        if not accept.all():
            self.counters.gated += int(np.count_nonzero(~accept))
            if not accept.any():
                return False
        p_phi = np.matmul(self.covariance, phi[:, :, None])[:, :, 0]
        gain = p_phi / (lam + (phi * p_phi).sum(axis=1))[:, None]
        estimate = np.clip(
            self._estimate + gain * error[:, None], -self.estimate_limit, self.estimate_limit
        )
        covariance = (self.covariance - gain[:, :, None] * p_phi[:, None, :]) / lam
        covariance, resets = stabilised(covariance, self._p0, self.config.max_variance)
        self.counters.resets += resets
        if accept.all():
            self._estimate, self.covariance = estimate, covariance
        else:
            rows = accept[:, None]
            self._estimate = np.where(rows, estimate, self._estimate)
            self.covariance = np.where(rows[:, :, None], covariance, self.covariance)
        self.theta = np.clip(self._estimate, -self.bounds, self.bounds)
        self.counters.updates += 1
        return True

    def restore(self, estimate: np.ndarray, error_scale: np.ndarray) -> None:
        """Continue from a stored estimate (n, 3) and error scale (n,); the prior covariance."""
        self._estimate = np.array(estimate, dtype=float)
        self.theta = np.clip(self._estimate, -self.bounds, self.bounds)
        self.error_scale = np.array(error_scale, dtype=float)

    @property
    def at_bounds(self) -> int:
        """Parameters whose estimate lies beyond its bound (the applied value is the bound)."""
        return int(np.count_nonzero(self.theta != self._estimate))

    def state(self, joints: tuple[str, ...]) -> dict[str, Any]:
        """The adapted parameters and counters, JSON-ready (for /diagnostics and the file)."""
        return {
            'joints': list(joints),
            'columns': list(COLUMNS),
            'theta': self.theta.tolist(),
            'estimate': self._estimate.tolist(),
            'error_scale_nm': self.error_scale.tolist(),
            'updates': self.counters.updates,
            'gated_joint_samples': self.counters.gated,
            'frozen_samples': self.counters.frozen,
            'parameters_at_bounds': self.at_bounds,
            'covariance_resets': self.counters.resets,
            'config': self.config.__dict__,
        }

    def save(
        self, artifact: Path, joints: tuple[str, ...], extra: dict[str, Any] | None = None
    ) -> Path:
        """Write the state as ``<artifact>.adaptation.json`` beside the artifact folder.

        Never into it: the artifact's files are hashed. Unconditional: the predictor saves
        through ``AdaptationLoop.save``, which keeps what an earlier session stored.
        """
        path = adaptation_path(artifact)
        tmp = path.with_suffix('.tmp')
        state = self.state(joints) | {ARTIFACT_HASH: model_identity(artifact)} | (extra or {})
        tmp.write_text(json.dumps(state, indent=2), encoding='utf-8')
        tmp.replace(path)
        return path


class AdaptationLoop:
    """Pairs each prediction with the measured currents of the same IPO cycle, and adapts.

    The predictor hands every sample it serves to ``serve``, which adds the corrections and
    remembers the model's tau_u and the state; the drive's currents of that cycle arrive with
    the same stamp (``measured``), after the prediction from a drive, before it from a replay of
    a bag, and the pair updates the adapters (``adaptation_pairing``: each side waits for the
    other, a prediction ``capacity`` cycles, a current ``measured_capacity``). A pair completed by
    a prediction is learnt from at the next currents message, off the path from reference to
    torque. Currents that find no prediction of their stamp in time (a cycle never served, a
    sender stamping them otherwise) are counted as unpaired and learnt nothing from; when
    pairing keeps failing (``UNPAIRED_WARN_AFTER`` in a row) the loop says so once, with the
    stamp offset it sees.

    Args:
        adapter: the friction RLS.
        torque_per_ampere: (n,) gear ratio times torque constant: tau_u = it * current.
        capacity: predictions kept waiting for their currents.
        inertia: the rigid body's RLS (a change of the base inertial parameters), or None.
        measured_capacity: currents kept waiting for their prediction.
    """

    def __init__(
        self,
        adapter: FrictionAdapter,
        torque_per_ampere: np.ndarray,
        capacity: int = PREDICTION_CAPACITY,
        inertia: InertiaAdapter | None = None,
        measured_capacity: int = MEASURED_CAPACITY,
    ) -> None:
        """Start with nothing to pair."""
        self.adapter = adapter
        self.inertia = inertia
        self.torque_per_ampere = np.asarray(torque_per_ampere, dtype=float)
        self.capacity = capacity
        self.pairing: StampPairing[_Served, _Measured] = StampPairing(capacity, measured_capacity)
        #: Pairs a prediction completed, learnt from at the next currents (or at ``finish``).
        self._ready: list[tuple[_Served, _Measured]] = []
        #: Where the references come from, for the unpaired warning (the node's input topic).
        self.reference_source = 'the reference topic (input_topic)'
        self._said_unpaired = False
        self._pairing_lines: list[str] = []
        #: Why the latest sample was frozen ('' if none was), for /diagnostics.
        self.frozen_reason = ''
        #: (kind, text) of each kind of freeze reason, the first time it occurs: the caller
        #: says it once and clears the list.
        self.new_reasons: list[tuple[str, str]] = []
        self._kinds_seen: set[str] = set()
        #: What the stored file gave at start (``load``); None: not looked at.
        self.base: StoredBase | None = None

    @property
    def unpaired(self) -> int:
        """Currents that found no prediction of their stamp in time."""
        return self.pairing.unpaired

    def freeze(self, kind: str, reason: str) -> bool:
        """Count a sample nothing was learnt from and why; False, as an update learning nothing.

        ``kind``: stale, fallback, names, length or non_finite (each kind is said once).
        """
        self.adapter.counters.frozen += 1
        self.frozen_reason = reason
        if kind not in self._kinds_seen:
            self._kinds_seen.add(kind)
            self.new_reasons.append((kind, reason))
        return False

    @property
    def session_updates(self) -> int:
        """Updates the active estimator accepted in this session."""
        return self.adapter.counters.updates if self.inertia is None else self.inertia.updates

    def serve(
        self,
        stamp_ns: int,
        state: tuple[np.ndarray, np.ndarray, np.ndarray],
        tau_model: np.ndarray,
        *,
        learn: bool = True,
    ) -> np.ndarray:
        """The model's tau_u (n,) at a reference state (q, v, a) with the corrections added.

        ``learn``: remember the sample for its currents (False while another model served it:
        its currents are then taken and learnt nothing from).
        """
        q, v, a = state
        if self.inertia is not None:  # friction and rigid body, estimated together
            regressor = self.inertia.regressor(q, v, a)
            tau = tau_model + self.inertia.correction(regressor)
        else:
            regressor = None
            tau = tau_model + self.adapter.correction(v)
        served = (v.copy(), regressor, tau_model.copy()) if learn else None
        pair = self.pairing.predicted(stamp_ns, served)
        if pair is not None:  # its currents came first: learnt from at the next ones
            self._ready.append(pair)
        out: np.ndarray = tau
        return out

    def measured(
        self,
        stamp_ns: int,
        currents: np.ndarray,
        *,
        stale: bool = False,
        names: Sequence[str] = (),
        source: str = 'measured currents',
    ) -> bool:
        """Take the currents (n,) [A] of one cycle; whether an adapter learnt in this call.

        The currents pair with the prediction of their stamp, now or when it is served; a pair
        that a prediction completed is learnt from first. With the rigid body adapted too, the
        joint estimator (``InertiaAdapter``) learns alone. ``stale``: the reference is stale
        (nothing is learnt from the pair). ``names`` (the joints in order) and ``source`` (the
        topic) name a frozen sample's cause and an unpaired topic.
        """
        learnt = self.learn_ready()
        measured = self.torque_per_ampere * np.asarray(currents, dtype=float)
        pair = self.pairing.measured(stamp_ns, (measured, stale, tuple(names), source))
        if not self._said_unpaired and self.pairing.unpaired_streak >= UNPAIRED_WARN_AFTER:
            self._said_unpaired = True
            self._pairing_lines.append(self._unpaired_line(source))
        if pair is None:
            return learnt
        return self._learn(*pair) or learnt

    def learn_ready(self) -> bool:
        """Learn from the pairs predictions completed since the last call; whether any learnt."""
        if not self._ready:
            return False
        ready, self._ready = self._ready, []
        learnt = False
        for served, current in ready:
            learnt = self._learn(served, current) or learnt
        return learnt

    def _learn(self, served: _Served, current: _Measured) -> bool:
        """Update the active estimator from one pair; whether it learnt."""
        measured, stale, names, source = current
        if served is None:
            return self.freeze(
                'fallback', f"{source}: the physics prior served the cycle, not the model's torque"
            )
        if stale:
            return self.freeze('stale', 'the reference is stale')
        if not np.isfinite(measured).all():
            bad = np.flatnonzero(~np.isfinite(measured)).tolist()
            which = [names[j] for j in bad] if len(names) == len(measured) else bad
            return self.freeze('non_finite', f'{source}: effort (current) of {which} not finite')
        v, regressor, tau_model = served
        if self.inertia is not None and regressor is not None:
            return self.inertia.update(regressor, measured - tau_model)
        return self.adapter.update(v, measured, tau_model)

    def _unpaired_line(self, source: str) -> str:
        """Why the adaptation learns nothing when pairing keeps failing, with the offset seen."""
        pairing, offset = self.pairing, self.pairing.offset_ns()
        seen = (
            'no prediction waits for currents: none was served to learn from'
            if offset is None
            else f"the latest one's stamp is {offset * 1e-6:+.3f} ms from the nearest served "
            "prediction's"
        )
        return (
            f'adaptation pairs no currents: the last {pairing.unpaired_streak} messages on '
            f'{source} found no prediction of the same stamp among the references served from '
            f'{self.reference_source} ({seen}); currents must carry the stamp of the reference '
            f'cycle they answer, arriving within {pairing.measured_capacity} cycles before its '
            f'prediction or {pairing.prediction_capacity} after (counted as adaptation_unpaired; '
            'said once)'
        )

    def take_reasons(self) -> list[tuple[bool, str]]:
        """(is a warning, log line) of each freeze reason new since the last call.

        A stale reference is normal (the end of a motion), and so is a cycle the physics prior
        served: said at the info level. Then the unpaired warning, once.
        """
        lines = [
            (
                kind not in ('stale', 'fallback'),
                f'adaptation learns nothing from a sample: {reason} (said once per kind; counted '
                'as adaptation_frozen, the latest reason as adaptation_frozen_reason)',
            )
            for kind, reason in self.new_reasons
        ]
        lines += [(True, line) for line in self._pairing_lines]
        self.new_reasons.clear()
        self._pairing_lines.clear()
        return lines

    def finish(self, artifact: Path, joints: Sequence[str]) -> tuple[bool, str]:
        """``save`` at the end of a session: (is a warning, a line saying what went where)."""
        self.learn_ready()
        base = self.base or unloaded_base(artifact)
        try:
            saved = save_state(self, tuple(joints), base)
        except OSError as err:
            return True, f'adapted parameters not saved: {err}'
        if saved is not None:
            return saved[0], f'adapted parameters saved to {saved[1]}: {saved[2]}'
        gated = self.adapter.counters.gated if self.inertia is None else self.inertia.gated
        frozen = (self.adapter.counters.frozen, self.frozen_reason or 'no paired currents')
        return unlearnt_line(gated, frozen, self.unpaired, base)

    def state(self, joints: tuple[str, ...]) -> dict[str, Any]:
        """The active estimator's state, JSON-ready.

        With the rigid body adapted, its joint estimate (friction terms and base-parameter
        changes, ``InertiaAdapter.state``) replaces the unused friction adapter's.
        """
        extra = {} if self.inertia is None else self.inertia.state()
        return self.adapter.state(joints) | extra

    def load(
        self, artifact: Path, joints: Sequence[str], model_sha256: str | None = None
    ) -> StoredBase:
        """Continue from ``<artifact>.adaptation.json`` when it fits (``adaptation_store``).

        ``model_sha256``: the loaded model's ``artifact_sha256`` (None: read from its model.json).
        """
        self.base = load_base(self, artifact, tuple(joints), model_sha256)
        return self.base

    def save(self, artifact: Path, joints: tuple[str, ...]) -> tuple[Path, str] | None:
        """Write the state where its model is if this session learnt: (path, what), or None.

        A file not looked at by ``load`` is not continued from: it is kept aside, not lost.
        """
        saved = save_state(self, joints, self.base or unloaded_base(artifact))
        return None if saved is None else (saved[1], saved[2])

    @classmethod
    def for_robot(
        cls,
        robot: RobotConfig,
        joints: tuple[str, ...],
        config: AdaptationConfig,
        *,
        inertia: bool = False,
    ) -> AdaptationLoop:
        """A loop for a robot's drives and limits, in the given joint order.

        ``inertia``: adapt the rigid body's base parameters too (``InertiaAdapter``).
        """
        order = [robot.joints.index(name) for name in joints]
        drives, limits = robot.drives, robot.limits
        adapter = FrictionAdapter(
            limits.torque[order], limits.velocity[order], robot.ipo_period_s, config
        )
        body = (
            InertiaAdapter(
                robot,
                joints,
                robot.ipo_period_s,
                config.time_constant_s,
                INERTIA_BOUND_SHARE,
                smoothing_velocity=config.smoothing_velocity,
                gate_sigmas=config.gate_sigmas,
                friction_prior=config.initial_std * BOUND_SHARE,
                max_variance=config.max_variance,
            )
            if inertia
            else None
        )
        return cls(adapter, torque_per_ampere(drives)[order], inertia=body)

    def measured_message(
        self,
        stamp_ns: int,
        names: Sequence[str],
        effort: Sequence[float],
        joints: Sequence[str],
        source: str = 'measured currents',
    ) -> bool:
        """``measured`` from a JointState's names and effort (the currents), in any order.

        A message whose names are not the joints, or whose effort does not match them, counts
        as frozen input (nothing learnt), with the reason naming ``source`` (the topic).
        """
        if len(names) != len(joints) or set(names) != set(joints):
            missing = [name for name in joints if name not in names]
            extra = [name for name in names if name not in joints]
            return self.freeze(
                'names',
                f"{source}: names {list(names)} are not the model's joints {list(joints)} "
                f'(missing {missing}, unexpected {extra})',
            )
        if len(effort) != len(names):
            return self.freeze(
                'length',
                f'{source}: effort has {len(effort)} values for {len(names)} names',
            )
        index = {name: k for k, name in enumerate(names)}
        currents = np.array([effort[index[name]] for name in joints], dtype=float)
        return self.measured(stamp_ns, currents, names=joints, source=source)

    def report(self, joints: Sequence[str]) -> dict[str, object]:
        """Diagnostics key-values: counts and each joint's adapted parameters."""
        counters, inertia = self.adapter.counters, self.inertia
        offset = self.pairing.offset_ns()
        values: dict[str, object] = {
            'adaptation_updates': counters.updates if inertia is None else inertia.updates,
            'adaptation_gated': counters.gated if inertia is None else inertia.gated,
            'adaptation_frozen': counters.frozen,
            'adaptation_unpaired': self.unpaired,
            'adaptation_unpaired_offset_ms': 'none' if offset is None else offset * 1e-6,
            'adaptation_frozen_reason': self.frozen_reason or 'none',
            'adaptation_at_bounds': self.adapter.at_bounds if inertia is None else 0,
        }
        theta = self.adapter.theta if self.inertia is None else self.inertia.friction
        for j, name in enumerate(joints):
            for k, column in enumerate(COLUMNS):
                values[f'adapted_{column}_{name}'] = float(theta[j, k])
        if self.inertia is not None:
            values['adapted_base_parameter_change_norm'] = float(
                np.linalg.norm(self.inertia.change)
            )
        return values
