"""The diagnosed physics model as a model kind: nominal RNEA plus named effects, optionally + MLP.

``rnea_effects`` is the augmented analytic model of ``id_learning.diagnosis``: the URDF's
rigid-body dynamics and datasheet drives (the nominal model) plus the physically named effects a
diagnosis found (friction laws, rotor inertia, balancer spring, payload, ...), each a group of
regressor columns with identified coefficients. ``rnea_effects_mlp`` puts the Newtonian
network's MLP h(q, v) on top of it, so the network only learns what the named effects leave.

Where the effects come from (``effects``):

- a diagnosis' ``effects.json`` (or its output folder): the terms are taken as identified there;
- empty (the default): the effects a diagnosis of the training part found
  (``TrainingData.diagnosed``; the trainer runs it, with the training part's last 30 % as the
  diagnosis' held-out part). The test part is never seen.

The signal-delay term needs the jerk, which the (q, v, a) interface does not carry: predictions
use zero jerk, i.e. keep the term's d tau / dq v + d tau / dv a part.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal, Self

import numpy as np

from id_learning.config_io import read_capped
from id_learning.errors import CheckpointError, ConfigError, RobotModelError
from id_learning.models.base import (
    InverseDynamicsModel,
    ModelConfig,
    SamplePredictor,
    TorqueComponents,
)
from id_learning.models.blackbox import check_kind
from id_learning.models.data import TrainingData
from id_learning.models.metadata_checks import DuplicateKeyError, loads_unique
from id_learning.models.network_common import NumpyNormalisedMlp
from id_learning.models.physics import RneaMlpConfig, RneaMlpModel
from id_learning.physics.augmented import EFFECTS_JSON, AugmentedModel
from id_learning.robot.config import RobotConfig

__all__ = [
    'RneaEffectsConfig',
    'RneaEffectsMlpConfig',
    'RneaEffectsMlpModel',
    'RneaEffectsModel',
    'load_effects_file',
]

_LOG = logging.getLogger(__name__)
#: The largest effects.json read (a diagnosis writes a few kB; a larger file is another one).
MAX_EFFECTS_BYTES = 16 * 2**20

#: Tensor-name prefix of the effect coefficients in an artifact.
TERM_PREFIX = 'effects.term.'


def load_effects_file(path: str | Path) -> dict[str, Any]:
    """The JSON of a diagnosis' effects.json, given the file or the diagnosis' output folder.

    Raises:
        ConfigError: the file is missing, holds a key twice in one object, or is not a
            diagnosis' effects.json.
    """
    path = Path(path)
    if path.is_dir():
        path = path / EFFECTS_JSON
    try:
        if not path.exists():
            raise ConfigError(f'effects: {path} does not exist (run `id-learning diagnose`)')
        data = loads_unique(
            read_capped(path, 'effects.json', MAX_EFFECTS_BYTES, regular=True).decode('utf-8')
        )
    except UnicodeDecodeError as err:
        raise ConfigError(f'effects: {path} is not UTF-8 text: {err}') from err
    except DuplicateKeyError as err:
        raise ConfigError(f'effects: {path}: {err}; the file was edited or is corrupt') from err
    except json.JSONDecodeError as err:
        raise ConfigError(f'effects: {path} is not valid JSON: {err}') from err
    if not isinstance(data, dict) or 'effects' not in data or 'joints' not in data:
        raise ConfigError(f'effects: {path} is not an effects.json written by a diagnosis')
    return data


def _effects_model(
    effects: str, data: TrainingData, robot: RobotConfig
) -> tuple[AugmentedModel, dict[str, Any]]:
    """The augmented model from a diagnosis file, or from the diagnosis of the training part.

    Raises:
        ConfigError: a bad effects file, or neither a file nor a diagnosis of the training part.
    """
    target = data.dataset.target
    if effects:
        saved = load_effects_file(effects)
        if saved.get('target', target) != target:
            raise ConfigError(
                f'effects: {effects} was diagnosed on the {saved["target"]!r} torque, but the '
                f'training target is {target!r}'
            )
        try:
            model = AugmentedModel.from_dict(saved.get('model', saved), robot)
        except Exception as err:  # a RobotModelError or a malformed entry
            raise ConfigError(f'effects: {effects} does not fit {robot.name}: {err}') from err
        return model, {'source': str(effects)}
    if data.diagnosed is None:
        raise ConfigError(
            'effects: no effects file given and no diagnosis of the training part: give a '
            "diagnosis' effects.json, or train through id_learning.training (or call "
            'id_learning.diagnosis.diagnose_training_part) to diagnose the training part'
        )
    return data.diagnosed.model, data.diagnosed.summary


def _terms_state(model: AugmentedModel) -> dict[str, np.ndarray]:
    return {f'{TERM_PREFIX}{i}': theta.copy() for i, (_, theta) in enumerate(model.terms)}


def _terms_metadata(model: AugmentedModel) -> dict[str, Any]:
    return {
        'target': model.target,
        'terms': [spec.to_dict() for spec, _ in model.terms],
        'nominal_joints': list(model.nominal_joints),
    }


def _load_terms(
    tensors: dict[str, np.ndarray], fitted: dict[str, Any], robot: RobotConfig, kind: str
) -> AugmentedModel:
    """Rebuild the augmented model from an artifact's tensors and fitted metadata.

    Raises:
        CheckpointError: the terms and the tensors do not match.
    """
    specs = fitted.get('terms')
    if not isinstance(specs, list) or 'target' not in fitted:
        raise CheckpointError(f'{kind}: the metadata lacks the effect terms and target')
    names = sorted(n for n in tensors if n.startswith(TERM_PREFIX))
    expected = [f'{TERM_PREFIX}{i}' for i in range(len(specs))]
    if names != sorted(expected):
        raise CheckpointError(f'{kind}: effect tensors {names} do not match {len(specs)} terms')
    data = {
        'robot': robot.name,
        'joints': list(robot.joints),
        'target': fitted['target'],
        'terms': [
            {'spec': spec, 'coefficients': np.asarray(tensors[name], dtype=float)}
            for spec, name in zip(specs, expected, strict=True)
        ],
        # Artifacts saved before the per-joint fallback add the effects on every joint.
        'nominal_joints': fitted.get('nominal_joints', []),
    }
    try:
        return AugmentedModel.from_dict(data, robot)
    except (KeyError, ValueError, TypeError, RobotModelError) as err:
        raise CheckpointError(f'{kind}: an effect term cannot be rebuilt: {err}') from err


# -- rnea_effects ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class RneaEffectsConfig(ModelConfig):
    """Settings of the diagnosed analytic model.

    Attributes:
        effects: a diagnosis' effects.json or output folder; empty: diagnose the training part.
        max_seconds: the time budget of the training part's diagnosis [s] (None: none); a
            diagnosis cut short by it says what it left out.
    """

    kind: Literal['rnea_effects'] = 'rnea_effects'
    effects: str = ''
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        """Check the kind and the budget."""
        check_kind(self, 'rnea_effects')
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise ConfigError(f'rnea_effects: max_seconds must be > 0, got {self.max_seconds}')


class RneaEffectsModel(InverseDynamicsModel):
    """tau = RNEA_URDF(q, v, a) [+ datasheet rotor inertia for tau_u] + sum of named effects."""

    kind: ClassVar[str] = 'rnea_effects'

    def __init__(self, config: RneaEffectsConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaEffectsConfig = config
        self.model_: AugmentedModel | None = None
        self.diagnosis_: dict[str, Any] = {}
        #: The training part's (q, v, a) range, for the predictor's out-of-range warning.
        self.input_range_: dict[str, Any] | None = None

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        """Take the effects of a diagnosis, or diagnose the training part."""
        data.require_varied(self.kind)
        del progress  # the diagnosis prints nothing; it takes seconds to a minute
        self.model_, self.diagnosis_ = _effects_model(self.config.effects, data, self.robot)
        self.input_range_ = data.dataset.input_scaler.to_dict()
        _LOG.info('rnea_effects: %d effect terms', len(self.model_.terms))
        return self

    @classmethod
    def from_augmented(cls, model: AugmentedModel, source: str = '') -> RneaEffectsModel:
        """Wrap a diagnosis' ``AugmentedModel`` (e.g. ``DiagnosisResult.augmented_model``)."""
        out = cls(RneaEffectsConfig(), model.robot)
        out.model_ = model
        out.diagnosis_ = {'source': source} if source else {}
        return out

    def _model(self) -> AugmentedModel:
        if self.model_ is None:
            raise CheckpointError(f'{self.kind}: the model is not fitted')
        return self.model_

    def predict(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Torque (B, n) [N*m] for q, v, a (B, n) [rad, rad/s, rad/s^2]."""
        torque: np.ndarray = self._model().torque(q, v, a)
        return torque

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque, the single-joint effects folded into vectorised calls."""
        sample_torque: SamplePredictor = self._model().sample_function()
        return sample_torque

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """The nominal model's torque, and what the named effects add to it as the residual."""
        model = self._model()
        total = model.torque(q, v, a)
        nominal = model.nominal.evaluate(
            np.atleast_2d(q), np.atleast_2d(v), np.atleast_2d(a)
        ).tau_nominal
        return TorqueComponents(total=total, residual=total - nominal)

    def state(self) -> dict[str, np.ndarray]:
        """The coefficients of every effect term, ``effects.term.<i>``."""
        return _terms_state(self._model())

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild the terms from their specs (metadata) and coefficients (tensors)."""
        self.model_ = _load_terms(tensors, fitted, self.robot, self.kind)
        self.diagnosis_ = dict(fitted.get('diagnosis', {}))
        self.input_range_ = fitted.get('input_scaler')

    def fitted_metadata(self) -> dict[str, Any]:
        """The target, each term's effect spec, where the effects came from, the input range."""
        out = {**_terms_metadata(self._model()), 'diagnosis': self.diagnosis_}
        if self.input_range_ is not None:
            out['input_scaler'] = self.input_range_
        return out


# -- rnea_effects_mlp -----------------------------------------------------------------------------
@dataclass(frozen=True)
class RneaEffectsMlpConfig(RneaMlpConfig):
    """The Newtonian network's settings, on top of the diagnosed model.

    Attributes:
        effects: as in ``RneaEffectsConfig``.
    """

    kind: Literal['rnea_effects_mlp'] = 'rnea_effects_mlp'
    effects: str = ''


class RneaEffectsMlpModel(RneaMlpModel):
    """tau = rnea_effects(q, v, a) + h(q, v): the MLP learns what the named effects leave."""

    kind: ClassVar[str] = 'rnea_effects_mlp'

    def __init__(self, config: RneaEffectsMlpConfig, robot: RobotConfig) -> None:
        """Store the settings; no I/O, no fitting."""
        super().__init__(config, robot)
        self.config: RneaEffectsMlpConfig = config
        self.effects_: AugmentedModel | None = None
        self.diagnosis_: dict[str, Any] = {}

    def training_physics(self, data: TrainingData) -> np.ndarray:
        """The diagnosed model's torque on every sample; the MLP fits the rest."""
        self.effects_, self.diagnosis_ = _effects_model(self.config.effects, data, self.robot)
        ds = data.dataset
        torque: np.ndarray = self.effects_.torque(ds.q, ds.v, ds.a)
        return torque

    def physics_torque(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The diagnosed model's torque (B, n) [N*m]."""
        torque: np.ndarray = self._effects().torque(q, v, a)
        return torque

    def _effects(self) -> AugmentedModel:
        """The diagnosed model.

        Raises:
            CheckpointError: the model is neither fitted nor loaded.
        """
        if self.effects_ is None:
            raise CheckpointError(f'{self.kind}: the model is not fitted')
        return self.effects_

    def sample_predictor(self) -> SamplePredictor:
        """One sample's torque: the diagnosed model's folded path plus h in float64 numpy."""
        effects = self._effects()
        h = NumpyNormalisedMlp(self.network())
        physics = effects.sample_function()

        def predict_one(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
            tau: np.ndarray = physics(q, v, a) + h(np.concatenate((q, v)))
            return tau

        return predict_one

    def components(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> TorqueComponents:
        """The total, with everything beyond the diagnosed model (h) as the residual."""
        physics = self.physics_torque(q, v, a)
        h = self.residual_torque(q, v)
        return TorqueComponents(total=physics + h, residual=h)

    def state(self) -> dict[str, np.ndarray]:
        """The weights of h and the coefficients of every effect term."""
        return {**super().state(), **_terms_state(self._effects())}

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        """Rebuild h and the effect terms."""
        network = {k: v for k, v in tensors.items() if not k.startswith(TERM_PREFIX)}
        super().load_state(network, fitted)
        self.effects_ = _load_terms(tensors, fitted, self.robot, self.kind)
        self.diagnosis_ = dict(fitted.get('diagnosis', {}))

    def fitted_metadata(self) -> dict[str, Any]:
        """The scalers and fit summary of h, the effect terms and where they came from."""
        out = super().fitted_metadata()
        out.pop('rotor_inertia_motor_side_kgm2', None)
        return {**out, **_terms_metadata(self._effects()), 'diagnosis': self.diagnosis_}
