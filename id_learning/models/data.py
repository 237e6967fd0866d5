"""Training data shared by all models: the preprocessed dataset plus nominal physics features."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from id_learning.dataset.preprocess import Dataset, MinMaxScaler
from id_learning.errors import DatasetError
from id_learning.physics.augmented import AugmentedModel
from id_learning.physics.identification import IdentificationConfig, identify
from id_learning.physics.identified import IdentifiedPhysics
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.robot import drives
from id_learning.robot.config import RobotConfig

__all__ = ['DiagnosedEffects', 'PhysicsFeatures', 'TrainingData', 'nominal_rnea']


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
    split the validation samples are drawn at random from the training ones. Rows are sorted
    index arrays. ``diagnosed`` holds
    the effects a diagnosis of the training part found, where the trainer ran one (the
    ``rnea_effects`` kinds without an effects file use them).
    """

    dataset: Dataset
    robot: RobotConfig
    validation_fraction: float = 0.15
    diagnosed: DiagnosedEffects | None = None
    #: Physics identified on the training part, per identification setting: ``rnea_id`` and
    #: ``rnea_id_mlp`` of one run share it (``identified``); kept by ``dataclasses.replace``.
    identifications: dict[str, IdentifiedPhysics] = field(default_factory=dict, repr=False)

    def identified(
        self, config: IdentificationConfig, deadline: float | None = None
    ) -> IdentifiedPhysics:
        """The physics identified on the training part with ``config``, once per setting.

        ``deadline``: the first identification's budget (``physics.identification.identify``).
        """
        key = repr(config)
        if key not in self.identifications:
            self.identifications[key] = identify(
                self.dataset, self.robot, config, deadline=deadline
            )
        return self.identifications[key]

    def require_varied(self, kind: str, *, inputs: bool = True) -> None:
        """Refuse to fit a model whose artifact would hold a scaler of zero width.

        A model stores the training part's range of each label column, and the kinds that
        scale their inputs the range of each of q, v and a per joint; loading refuses a range
        of zero width (``metadata_checks``), so a column constant on the training part (a joint
        that never moved, a robot standing still) is refused here, before the fit.

        Args:
            kind: the model kind, for the message.
            inputs: whether the kind stores the inputs' ranges (all but rnea_lq).

        Raises:
            DatasetError: names the columns that never varied.
        """
        ds = self.dataset
        checked: list[tuple[MinMaxScaler, tuple[str, ...]]] = [(ds.target_scaler, ('tau',))]
        if inputs:
            checked.insert(0, (ds.input_scaler, ('q', 'v', 'a')))
        constant: list[str] = []
        for scaler, quantities in checked:
            if scaler.low_ is None or scaler.high_ is None:
                continue
            names = [f'{x} of {joint}' for x in quantities for joint in ds.joints]
            flat = np.flatnonzero(np.asarray(scaler.high_) == np.asarray(scaler.low_))
            constant += [names[k] for k in flat if k < len(names)]
        if constant:
            raise DatasetError(
                f'{kind}: {", ".join(constant)} never varied in the training part (constant): '
                'a model stores the range of each column it was fitted on, and a column '
                'without one cannot be scaled nor the model loaded; record the joints moving'
                + ('' if not inputs else ' (rnea_lq stores no input ranges)')
            )

    @cached_property
    def physics(self) -> PhysicsFeatures:
        """Nominal physics features of every sample (computed on first use)."""
        ds = self.dataset
        return PhysicsFeatures(
            rnea=nominal_rnea(self.robot, ds.q, ds.v, ds.a),
            rotor_basis=drives.rotor_basis(ds.a, self.robot.drives.gear_ratio),
        )

    @property
    def n_fit(self) -> int:
        """Samples used for fitting: the training part minus its validation samples."""
        return round(self.dataset.n_train * (1.0 - self.validation_fraction))

    @cached_property
    def _fit_and_validation(self) -> tuple[np.ndarray, np.ndarray]:
        """The fit and validation rows.

        The training part's tail validates (contiguous split), or samples drawn from the
        training ones (shuffled; seeded by the split itself, so that another --split-seed draws
        other validation samples too).
        """
        train = self.dataset.train_rows
        mask = self.dataset.train_mask
        if mask is None:
            return train[: self.n_fit], train[self.n_fit :]
        seed = int.from_bytes(np.packbits(mask).tobytes()[:8] or b'0', 'little')
        order = np.random.default_rng([seed, len(train)]).permutation(len(train))
        return np.sort(train[order[: self.n_fit]]), np.sort(train[order[self.n_fit :]])

    @property
    def fit_rows(self) -> np.ndarray:
        """Rows of the fitting part."""
        return self._fit_and_validation[0]

    @property
    def validation_rows(self) -> np.ndarray:
        """Rows of the validation part (the training part's tail, or its drawn samples)."""
        return self._fit_and_validation[1]

    @property
    def train_rows(self) -> np.ndarray:
        """Rows of the whole training part (fit + validation)."""
        return self.dataset.train_rows

    @property
    def test_rows(self) -> np.ndarray:
        """Rows of the test part."""
        return self.dataset.test_rows
