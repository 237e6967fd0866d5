"""What one reference sample led to (``StepResult``, ``Reject``) and the running counts."""

from __future__ import annotations

import enum
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

__all__ = ['PredictorCounters', 'Reject', 'StepResult']


class Reject(enum.Enum):
    """Why a sample produced no model torque.

    INCONSISTENT (the sample does not follow from the ones before it) and REARMING (it does, but
    too few have since the last that did not) may still carry the hold output
    (``predictor.output``); every other reason carries no torque.
    """

    JOINT_COUNT = 'joint_count'
    JOINT_NAMES = 'joint_names'
    SHAPE = 'shape'
    NON_FINITE = 'non_finite'
    STAMP_ORDER = 'stamp_order'
    TOO_OLD = 'too_old'
    FUTURE_STAMP = 'future_stamp'
    INCONSISTENT = 'inconsistent'
    REARMING = 'rearming'
    OUT_OF_RANGE = 'out_of_range'
    IMPOSSIBLE = 'impossible'
    NON_FINITE_OUTPUT = 'non_finite_output'


@dataclass(frozen=True, eq=False)
class StepResult:
    """The outcome of one sample.

    Attributes:
        stamp_ns: the sample's stamp [ns] (stamp the output with it).
        tau: (n,) the torque to publish [N*m] in the model's joint order (clamped and
            slew-limited; the hold output when ``is_held``), or None: publish nothing.
        reject: why there is no torque, or None.
        detail: a human-readable reason (reject or range warning), or None.
        is_clamped: at least one joint was clamped.
        is_slew_limited: at least one joint was slew-limited.
        is_held: tau is the hold output, not the model's (see ``reject``).
        resynced: this sample started a new time base (``predictor.stamps``).
        is_out_of_range: the input left the training range (widened by its margin).
        physics_share: the share of the physics prior in tau (out_of_range 'fallback'): 0 inside
            the training range, 1 beyond its margin.
        resumed_after_stale: this sample ended a stale episode (the history was reset if the
            stamps jumped).
    """

    stamp_ns: int
    tau: np.ndarray | None
    reject: Reject | None = None
    detail: str | None = None
    is_clamped: bool = False
    is_slew_limited: bool = False
    is_held: bool = False
    resynced: bool = False
    is_out_of_range: bool = False
    resumed_after_stale: bool = False
    physics_share: float = 0.0


@dataclass
class PredictorCounters:
    """What happened since start.

    Attributes:
        received: samples passed to step().
        predicted: samples that produced a model torque.
        clamped_samples: predictions with at least one clamped joint.
        clamped_per_joint: (n,) clamps per joint.
        rejects: count per reject reason.
        slew_limited_samples: published torques with at least one slew-limited joint.
        slew_limited_per_joint: (n,) slew-limited torques per joint.
        held_samples: hold outputs published (no model torque: inconsistent or re-arming).
        resyncs: new time bases started after rejections for time in a row.
        out_of_range: samples outside the training range widened by its margin (warned,
            rejected or served by the physics prior alone).
        fallback_samples: samples whose torque holds a share of the physics prior (beyond the
            training range itself, margin included).
        stale_episodes: times the reference went stale after having been live.
        history_resets: times the history was reset (after a stale episode or a stamp gap).
        skipped_cycles: IPO cycles the stamps of consecutive accepted samples jump over, within
            the stale threshold: samples that never reached the predictor (not sent, lost on the
            way, or overwritten in a full queue) or were rejected.
    """

    n_joints: int
    received: int = 0
    predicted: int = 0
    clamped_samples: int = 0
    clamped_per_joint: np.ndarray = field(init=False)
    slew_limited_samples: int = 0
    slew_limited_per_joint: np.ndarray = field(init=False)
    held_samples: int = 0
    resyncs: int = 0
    rejects: Counter[Reject] = field(default_factory=Counter)
    out_of_range: int = 0
    fallback_samples: int = 0
    stale_episodes: int = 0
    history_resets: int = 0
    skipped_cycles: int = 0

    def __post_init__(self) -> None:
        self.clamped_per_joint = np.zeros(self.n_joints, dtype=np.int64)
        self.slew_limited_per_joint = np.zeros(self.n_joints, dtype=np.int64)

    @property
    def published(self) -> int:
        """Torques given to publish: the model's and hold outputs."""
        return self.predicted + self.held_samples

    @property
    def rejected(self) -> int:
        """All samples without a model torque."""
        return sum(self.rejects.values())

    def count_output(self, over: np.ndarray, slewed: np.ndarray) -> tuple[bool, bool]:
        """Count a served torque's clamped and slew-limited joints; (clamped, slew-limited)."""
        is_clamped, is_slewed = bool(over.any()), bool(slewed.any())
        if is_clamped:
            self.clamped_samples += 1
            self.clamped_per_joint += over
        if is_slewed:
            self.slew_limited_samples += 1
            self.slew_limited_per_joint += slewed
        return is_clamped, is_slewed
