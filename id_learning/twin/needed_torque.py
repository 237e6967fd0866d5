"""The torque a drive needs on a twin recording: the noise-free torque now, on the planned motion.

A twin's noise-free label (``tau_u_clean``) is the torque of the motion at t - delay: the
currents lag the motion (``signal_delay``). A feed-forward is asked for the torque of the motion
a controller plans for t, which it sends as its reference. On a twin bag both are known exactly:
the excitation's coefficients (ground_truth.json) give the planned motion, and the hidden robot
(drawn from twin_config.yaml beside the bag, as ``simulate`` draws it) gives its torque.

For target 'motor' the needed torque is what ``simulate`` puts in tau_u_clean with the delay
switched off: ``TwinPlant.motor_torque`` (rigid body, rotor inertia, balancer, friction, cogging)
on the planned motion at the sample time, divided by the torque-constant scale, plus the current
sensor's offset. For target 'joint' it is the torque at the gear output on the same motion (rigid
body less the balancer), what a joint torque sensor sees; the recorded joint-torque labels are
already of the motion at the sample time, while ``tau_joint_clean`` beside them is of the delayed
motion, as the currents are.

The reference a model is evaluated on is that planned motion as a controller holds it: positions
in the encoder's coordinates (q - joint offset, as ``simulate`` records them, not quantised),
velocities and accelerations exact.

Before it is used, the same computation on the delayed motion must give back the stored label
torque at every stamp to float32 precision; a bag simulated with another robot config or another
version of the twin is refused with the reason.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from id_learning.dataset.inputs import Motion
from id_learning.dataset.preprocess import Dataset
from id_learning.errors import ConfigError
from id_learning.record.excitation import ExcitationTrajectory
from id_learning.twin.effects import GravitySpring, SignalDelay
from id_learning.twin.ground_truth import read_ground_truth
from id_learning.twin.plant import TwinPlant
from id_learning.twin.simulate import (
    GROUND_TRUTH_ARRAYS,
    GROUND_TRUTH_JSON,
    TWIN_CONFIG_COPY,
    load_twin_config,
)

__all__ = [
    'NEEDED_TORQUE',
    'NEEDED_TORQUE_NOTES',
    'NeededTorque',
    'join_needed_torque',
    'needed_torque',
    'needed_torque_of',
]

_LOG = logging.getLogger(__name__)

#: ``Dataset.extra`` key of the needed torque along the dataset's rows (a ``NeededTorque``).
NEEDED_TORQUE = 'needed_torque'
#: ``Dataset.extra`` key of why a twin bag gave no needed torque: the reasons, each once.
NEEDED_TORQUE_NOTES = 'needed_torque_notes'

#: Relative resolution of the stored float32 label torque, with room for the rounding of two
#: ways of summing the same terms (~1e-12 N*m): a recomputation within it is the same one.
_FLOAT32_RESOLUTION = 1e-6


@dataclass(frozen=True, eq=False)
class NeededTorque:
    """The planned motion of a twin recording and the torque a drive needs on it.

    Attributes:
        reference: the planned motion at the rows' stamps, each (N, n): q in the encoder's
            coordinates [rad], v [rad/s], a [rad/s^2], exact.
        torque: (N, n) the noise-free torque of the dataset's target on the reference at each
            sample time, without the label's delay [N*m].
    """

    reference: Motion
    torque: np.ndarray

    def take(self, rows: slice | np.ndarray) -> NeededTorque:
        """The needed torque on some rows."""
        return NeededTorque(self.reference.take(rows), self.torque[rows])

    @classmethod
    def concatenate(cls, parts: Sequence[NeededTorque]) -> NeededTorque:
        """Needed torques one after the other."""
        return cls(
            Motion.concatenate([p.reference for p in parts]),
            np.concatenate([p.torque for p in parts]),
        )


def needed_torque_of(dataset: Dataset) -> NeededTorque | None:
    """The needed torque a dataset carries (``load_datasets`` puts it there), or None."""
    needed = dataset.extra.get(NEEDED_TORQUE)
    return needed if isinstance(needed, NeededTorque) else None


def join_needed_torque(pieces: Sequence[tuple[Dataset, slice]]) -> NeededTorque | None:
    """The needed torque of rows of datasets joined in order; None unless each carries one."""
    parts = [(needed_torque_of(d), rows) for d, rows in pieces]
    taken = [needed.take(rows) for needed, rows in parts if needed is not None]
    return NeededTorque.concatenate(taken) if taken and len(taken) == len(parts) else None


def needed_torque(bag: Path | str, dataset: Dataset) -> tuple[NeededTorque | None, str]:
    """The planned reference and the torque the drive needs at a twin dataset's stamps.

    Recomputed from the twin config and the excitation beside the bag (see the module
    docstring); about a second for a 600 s recording.

    Args:
        bag: the bag folder the dataset was loaded from.
        dataset: one preprocessed segment of it (its target, joints and stamps).

    Returns:
        (the needed torque in the dataset's joint order, '') for a twin bag; (None, '') for a
        bag without a ground truth; (None, why) when it cannot be recomputed: the reason names
        the file and what is missing or differs.

    Raises:
        DatasetError: ground_truth.json or ground_truth.npz is damaged (``read_ground_truth``).
    """
    folder = Path(bag)
    ignored = 'no error against the torque the drive needs for this bag'
    truth = read_ground_truth(folder, dataset.target)
    if truth is None:
        if (folder / GROUND_TRUTH_ARRAYS).is_file():
            return None, (
                f'{folder / GROUND_TRUTH_JSON}: missing beside {GROUND_TRUTH_ARRAYS}, so the '
                f'planned motion is unknown; {ignored}'
            )
        return None, ''
    config_path = folder / TWIN_CONFIG_COPY
    if not config_path.is_file():
        return None, f'{config_path}: missing beside {GROUND_TRUTH_JSON}; {ignored}'
    try:
        config = load_twin_config(config_path)
    except ConfigError as err:
        return None, f'{config_path}: cannot rebuild the twin: {err}; {ignored}'
    try:
        trajectory = ExcitationTrajectory.from_dict(truth.info['excitation'])
    except (KeyError, TypeError, ValueError) as err:
        return None, (
            f'{folder / GROUND_TRUTH_JSON}: no usable excitation coefficients '
            f'({type(err).__name__}: {err}); {ignored}'
        )
    robot = config.robot
    if sorted(robot.joints) != sorted(dataset.joints):
        return None, (
            f'{config_path}: its robot has the joints {", ".join(robot.joints)}, the recording '
            f'{", ".join(dataset.joints)}; {ignored}'
        )
    order = [robot.joints.index(j) for j in dataset.joints]
    # The simulation's own sample times, so that t is bit for bit the one simulate used.
    t_all = np.arange(round(trajectory.duration_s / robot.ipo_period_s) + 1) * robot.ipo_period_s
    stamps = config.start_time_ns + np.round(t_all * 1e9).astype(np.int64)
    rows = np.minimum(np.searchsorted(stamps, dataset.stamps_ns), len(stamps) - 1)
    if not np.array_equal(stamps[rows], dataset.stamps_ns) or truth.tau_clean.shape != (
        len(stamps),
        robot.n_joints,
    ):
        return None, (
            f'{folder}: the stamps of the recording ({len(dataset.stamps_ns)} samples) or of '
            f'{GROUND_TRUTH_ARRAYS} ({len(truth.tau_clean)}) are not those of the simulation '
            f'{config_path.name} and the excitation describe ({len(stamps)} samples of '
            f'{robot.ipo_period_s:g} s from {config.start_time_ns} ns); {ignored}'
        )
    t = t_all[rows]
    plant = TwinPlant(config)
    delay = config.effects.get('signal_delay')
    assert isinstance(delay, SignalDelay)
    delay_s = delay.delay_s if delay.enabled else 0.0
    label = _noise_free_torque(plant, trajectory, t - delay_s, dataset.target)
    mismatch = _label_mismatch(label, truth.tau_clean[rows], robot.joints, dataset.target)
    if mismatch:
        return None, f'{folder / GROUND_TRUTH_ARRAYS}: {mismatch}; {ignored}'
    torque = _noise_free_torque(plant, trajectory, t, dataset.target) if delay_s else label
    q, v, a = trajectory.evaluate(t)
    reference = Motion((q - plant.encoder_offset)[:, order], v[:, order], a[:, order])
    _LOG.debug('%s: needed torque on %d samples (delay %g s)', folder, len(t), delay_s)
    return NeededTorque(reference, torque[:, order]), ''


def _noise_free_torque(
    plant: TwinPlant, trajectory: ExcitationTrajectory, t: np.ndarray, target: str
) -> np.ndarray:
    """(N, n) the twin's noise-free torque of the target on the planned motion at times t [s].

    'motor': tau_u as a perfect current sensor gives it (``simulate``'s tau_u_clean without its
    delay); 'joint': the torque at the gear output.
    """
    q, v, a = trajectory.evaluate(t)
    if target == 'joint':
        spring = plant.config.effects.get('gravity_spring')
        assert isinstance(spring, GravitySpring)
        link: np.ndarray = plant.dynamics.rnea(q, v, a)
        if spring.enabled:
            j = plant.robot.joints.index(spring.joint)
            link[:, j] -= spring.torque_on_joint(q[:, j])
        return link
    return plant.command(q, v, a, t)


def _label_mismatch(
    label: np.ndarray, stored: np.ndarray, joints: tuple[str, ...], target: str
) -> str:
    """Why the recomputed label torque is not the stored one ('' when equal to float32)."""
    off = np.abs(label - stored)
    allowed = _FLOAT32_RESOLUTION * (np.max(np.abs(stored), axis=0) + 1.0)
    bad = ~(np.max(off, axis=0) <= allowed)  # NaN counts as off
    if not bad.any():
        return ''
    j = int(np.argmax(np.where(bad, np.max(off, axis=0) / allowed, -np.inf)))
    k = int(np.argmax(off[:, j]))
    key = 'tau_u_clean' if target == 'motor' else 'tau_joint_clean'
    return (
        f'recomputing its {key} from {TWIN_CONFIG_COPY} and the excitation in '
        f'{GROUND_TRUTH_JSON} gives {label[k, j]:.6g} N*m on {joints[j]} at sample {k}, it '
        f'holds {stored[k, j]:.6g} (float32 allows {allowed[j]:.2g}): the robot config or the '
        'twin changed since the bag was simulated; re-run simulate'
    )
