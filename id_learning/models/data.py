"""Training data shared by all models: the preprocessed dataset plus nominal physics features."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.physics.augmented import AugmentedModel
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot.config import RobotConfig

__all__ = ['DiagnosedEffects', 'PhysicsFeatures', 'Rows', 'TrainingData', 'nominal_rnea']

#: Rows of a part: a slice (contiguous split) or sorted row indices (shuffled split).
Rows = slice | np.ndarray


def nominal_rnea(robot: RobotConfig, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """RNEA with the URDF's (manufacturer's) parameters, (B, n) [N*m]."""
    return RigidBodyDynamics.from_config(robot).rnea(q, v, a)


@dataclass(frozen=True, eq=False)
class PhysicsFeatures:
    """Nominal-model quantities per sample, computed once and shared by the physics models.

    Attributes:
        rnea: (N, n) URDF rigid-body torque [N*m].
        rotor_basis: (N, n) gear_ratio**2 * a: rotor torque per unit motor-side inertia.
    """

    rnea: np.ndarray
    rotor_basis: np.ndarray


@dataclass(frozen=True, eq=False)
class DiagnosedEffects:
    """The effects a diagnosis of the training part found, for the kinds built on them.

    Attributes:
        model: the nominal model plus the effects, identified on the training part.
        summary: JSON-ready record of where they came from (named effects, alias sets, ...).
    """

    model: AugmentedModel
    summary: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class TrainingData:
    """A preprocessed dataset with its robot, split into fit / validation / test parts.

    The training part (the first ``dataset.n_train`` samples) is split again in time: its last
    ``validation_fraction`` is the validation part used for early stopping. Under a shuffled
    split the validation samples are drawn at random from the training ones, and the rows are
    index arrays instead of slices (``Rows``: both index numpy arrays alike). ``diagnosed`` holds
    the effects a diagnosis of the training part found, where the trainer ran one (the
    ``rnea_effects`` kinds without an effects file use them).
    """

    dataset: Dataset
    robot: RobotConfig
    validation_fraction: float = 0.15
    diagnosed: DiagnosedEffects | None = None

    @cached_property
    def physics(self) -> PhysicsFeatures:
        """Nominal physics features of every sample (computed on first use)."""
        ds = self.dataset
        return PhysicsFeatures(
            rnea=nominal_rnea(self.robot, ds.q, ds.v, ds.a),
            rotor_basis=ds.a * self.robot.drives.gear_ratio**2,
        )

    @property
    def n_fit(self) -> int:
        """Samples used for fitting: the training part minus its validation samples."""
        return round(self.dataset.n_train * (1.0 - self.validation_fraction))

    @cached_property
    def _shuffled_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """A shuffled split's fit and validation rows.

        The validation samples are drawn at random from the training ones (seeded), as the split
        drew those.
        """
        train = self.dataset.train_rows
        mask = self.dataset.train_mask
        assert mask is not None
        # Seeded by the split itself: another --split-seed draws other validation samples too.
        seed = int.from_bytes(np.packbits(mask).tobytes()[:8] or b'0', 'little')
        order = np.random.default_rng([seed, len(train)]).permutation(len(train))
        return np.sort(train[order[: self.n_fit]]), np.sort(train[order[self.n_fit :]])

    @property
    def fit_rows(self) -> Rows:
        """Rows of the fitting part."""
        if self.dataset.is_shuffled:
            return self._shuffled_parts[0]
        return slice(0, self.n_fit)

    @property
    def validation_rows(self) -> Rows:
        """Rows of the validation part (the training part's tail, or its drawn samples)."""
        if self.dataset.is_shuffled:
            return self._shuffled_parts[1]
        return slice(self.n_fit, self.dataset.n_train)

    @property
    def train_rows(self) -> Rows:
        """Rows of the whole training part (fit + validation)."""
        if self.dataset.is_shuffled:
            return self.dataset.train_rows
        return slice(0, self.dataset.n_train)

    @property
    def test_rows(self) -> Rows:
        """Rows of the test part."""
        if self.dataset.is_shuffled:
            return self.dataset.test_rows
        return slice(self.dataset.n_train, None)
