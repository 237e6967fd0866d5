"""Feed-forward in the loop: the twin as the plant under a controller stand-in.

A trained model earns its place when a controller tracks better with its tau_u as
feed-forward. Here the twin's hidden robot (``twin.TwinPlant``) is driven at the IPO rate by a
cascaded position P / velocity PI controller, as a drive does it, with the current (torque)
limit and the twin's sensors (encoder offset and resolution, velocity noise): once on feedback
alone, once per model with its tau_u along the reference as feed-forward, and once with the
twin's true inverse dynamics. The tracking error is the true position's distance from the
reference.

Gains: the velocity loop's bandwidth is ``VELOCITY_BANDWIDTH_HZ`` on each joint's inertia at the
reference's mean pose (rotor included), the integrator's corner a quarter of it, the position
loop's a quarter of it too: a stiff but realistic loop for a heavy arm closed at 8 ms, which
leaves to the feed-forward the torque that feedback alone would need an error to produce.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from id_learning.dataset.inputs import Motion
from id_learning.twin.plant import TwinPlant

__all__ = [
    'FEEDBACK_ONLY',
    'TRUE_DYNAMICS',
    'VELOCITY_BANDWIDTH_HZ',
    'LoopGains',
    'Tracking',
    'compare_feed_forward',
    'improvement',
    'reference_gains',
    'track',
]

#: The velocity loop's bandwidth [Hz] (a PI velocity loop closed at the 8 ms IPO rate).
VELOCITY_BANDWIDTH_HZ = 4.0
#: Plant integration steps per IPO cycle.
SUBSTEPS = 4
FEEDBACK_ONLY = 'feedback only'
TRUE_DYNAMICS = 'true inverse dynamics'


@dataclass(frozen=True)
class LoopGains:
    """Per joint: position gain [1/s], velocity gain [N*m*s/rad], integral gain [N*m/rad]."""

    position: np.ndarray
    velocity: np.ndarray
    integral: np.ndarray

    @classmethod
    def for_plant(
        cls, plant: TwinPlant, q: np.ndarray, bandwidth_hz: float = VELOCITY_BANDWIDTH_HZ
    ) -> LoopGains:
        """Gains tuned on each joint's inertia at pose q (n,) (see the module docstring)."""
        mass, _ = plant.dynamics.sample_mass_and_bias()(q, np.zeros_like(q))
        inertia = np.diag(mass) + plant.rotor_inertia_joint_side
        omega = 2.0 * np.pi * bandwidth_hz
        velocity = inertia * omega
        return cls(np.full_like(inertia, omega / 4.0), velocity, velocity * omega / 4.0)


@dataclass(frozen=True)
class Tracking:
    """One closed-loop run along a reference.

    Attributes:
        error: (N, n) reference minus true position at each IPO cycle [rad].
        command: (N, n) the torque commanded [N*m, tau_u units].
        saturated: (n,) cycles in which the command hit the torque limit.
        diverged_at: the cycle at which the loop went unstable (a feed-forward no drive could
            follow, a non-finite one), or None; errors are infinite then.
    """

    error: np.ndarray
    command: np.ndarray
    saturated: np.ndarray
    diverged_at: int | None = None

    @property
    def rms(self) -> np.ndarray:
        """(n,) RMS tracking error [rad] (inf when the loop diverged)."""
        if self.diverged_at is not None:
            return np.full(self.error.shape[1], np.inf)
        out: np.ndarray = np.sqrt(np.mean(self.error**2, axis=0))
        return out

    @property
    def max(self) -> np.ndarray:
        """(n,) largest tracking error [rad] (inf when the loop diverged)."""
        if self.diverged_at is not None:
            return np.full(self.error.shape[1], np.inf)
        out: np.ndarray = np.max(np.abs(self.error), axis=0)
        return out


def track(
    plant: TwinPlant,
    reference: Motion,
    feed_forward: np.ndarray,
    gains: LoopGains,
    *,
    period_s: float,
    seed: int = 0,
) -> Tracking:
    """Run the loop along a reference (N, n) in the sensors' coordinates.

    Args:
        plant: the twin's robot.
        reference: the motion to track, as the controller sees positions (with the encoder
            offset the twin's sensors have), velocities and accelerations.
        feed_forward: (N, n) tau_u added to the controller's output [N*m].
        gains: the controller's gains.
        period_s: the IPO period [s].
        seed: the sensor noise's seed (the same for every run compared).
    """
    rng = np.random.default_rng(seed)
    measurement = plant.config.measurement
    counts = measurement.encoder_counts_per_motor_turn
    resolution = 2 * np.pi / (counts * plant.gear) if counts else None
    limit = plant.robot.limits.torque
    offset = plant.encoder_offset
    state = plant.start(reference.q[0] + offset, reference.v[0])
    integral = np.zeros(plant.robot.n_joints)
    n = len(reference.q)
    error, command = np.empty_like(reference.q), np.empty_like(reference.q)
    saturated = np.zeros(plant.robot.n_joints, dtype=int)
    dt = period_s / SUBSTEPS
    for k in range(n):
        q_seen = state.q - offset
        if resolution is not None:
            q_seen = np.round(q_seen / resolution) * resolution
        v_seen = state.v + measurement.velocity_noise_std * rng.standard_normal(len(state.v))
        error[k] = reference.q[k] + offset - state.q
        v_command = reference.v[k] + gains.position * (reference.q[k] - q_seen)
        v_error = v_command - v_seen
        tau = gains.velocity * v_error + gains.integral * integral + feed_forward[k]
        clipped = np.clip(tau, -limit, limit)
        hit = clipped != tau
        saturated += hit
        integral += np.where(hit, 0.0, v_error * period_s)  # no wind-up at the limit
        command[k] = clipped
        for _ in range(SUBSTEPS):
            state = plant.step(state, clipped, dt)
        if not (np.isfinite(state.q).all() and np.isfinite(tau).all()):
            return Tracking(error, command, saturated, diverged_at=k)
    return Tracking(error, command, saturated)


def compare_feed_forward(
    plant: TwinPlant,
    reference: Motion,
    feed_forwards: Mapping[str, np.ndarray],
    *,
    period_s: float,
    gains: LoopGains | None = None,
    progress: bool = True,
) -> dict[str, Tracking]:
    """Track the reference with feedback alone, then with each feed-forward (name -> (N, n)).

    The gains default to those of the plant at the reference's mean pose (``reference_gains``);
    the sensor noise is the same in every run.
    """
    gains = gains or reference_gains(plant, reference)
    runs = {FEEDBACK_ONLY: np.zeros_like(reference.q), **feed_forwards}
    return {
        name: track(plant, reference, ff, gains, period_s=period_s)
        for name, ff in tqdm(runs.items(), desc='closed loop', unit='run', disable=not progress)
    }


def reference_gains(plant: TwinPlant, reference: Motion) -> LoopGains:
    """The loop's gains on the plant's inertia at the reference's mean pose."""
    return LoopGains.for_plant(plant, np.mean(reference.q, axis=0) + plant.encoder_offset)


def improvement(runs: Mapping[str, Tracking], models: list[str]) -> tuple[str, np.ndarray]:
    """The best model and, per joint, feedback alone's RMS error divided by the best model's.

    The best model has the smallest mean (over joints) RMS error relative to feedback alone.
    """
    base = runs[FEEDBACK_ONLY].rms
    scores = {name: float(np.mean(runs[name].rms / base)) for name in models}
    if not scores:
        raise ValueError('no model to compare with feedback alone')
    best = min(scores, key=scores.__getitem__)
    return best, base / runs[best].rms
