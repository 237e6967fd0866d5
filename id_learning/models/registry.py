"""Model kinds by name, and saving/loading any of them as an artifact folder."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.artifact import (
    ArtifactExtra,
    artifact_target,
    read_artifact,
    write_artifact,
)
from id_learning.models.base import InverseDynamicsModel, ModelConfig, as_sequence_model
from id_learning.models.blackbox import LstmConfig, LstmModel, MlpConfig, MlpModel
from id_learning.models.effects import (
    RneaEffectsConfig,
    RneaEffectsMlpConfig,
    RneaEffectsMlpModel,
    RneaEffectsModel,
)
from id_learning.models.hyper_schema import check_hyper
from id_learning.models.identified import (
    RneaIdConfig,
    RneaIdMlpConfig,
    RneaIdMlpModel,
    RneaIdModel,
)
from id_learning.models.lagrangian import (
    DelanConfig,
    DelanModel,
    LnnConfig,
    LnnMlpConfig,
    LnnMlpModel,
    LnnModel,
)
from id_learning.models.lagrangian_id import (
    DelanIdConfig,
    DelanIdModel,
    LnnMlpIdConfig,
    LnnMlpIdModel,
)
from id_learning.models.physics import RneaLqConfig, RneaLqModel, RneaMlpConfig, RneaMlpModel
from id_learning.robot.config import RobotConfig

__all__ = ['MODEL_KINDS', 'STUDY_MODELS', 'load_model', 'make_config', 'make_model', 'save_model']

_LOG = logging.getLogger(__name__)

MODEL_KINDS: dict[str, tuple[type[ModelConfig], type[InverseDynamicsModel]]] = {
    'rnea_lq': (RneaLqConfig, RneaLqModel),
    'rnea_mlp': (RneaMlpConfig, RneaMlpModel),
    'delan': (DelanConfig, DelanModel),
    'lnn': (LnnConfig, LnnModel),
    'lnn_mlp': (LnnMlpConfig, LnnMlpModel),
    'mlp': (MlpConfig, MlpModel),
    'lstm': (LstmConfig, LstmModel),
    'rnea_effects': (RneaEffectsConfig, RneaEffectsModel),
    'rnea_effects_mlp': (RneaEffectsMlpConfig, RneaEffectsMlpModel),
    'rnea_id': (RneaIdConfig, RneaIdModel),
    'rnea_id_mlp': (RneaIdMlpConfig, RneaIdMlpModel),
    'delan_id': (DelanIdConfig, DelanIdModel),
    'lnn_mlp_id': (LnnMlpIdConfig, LnnMlpIdModel),
}

#: The reference study's seven models, in its table order.
STUDY_MODELS = ('rnea_lq', 'rnea_mlp', 'delan', 'lnn', 'lnn_mlp', 'mlp', 'lstm')

#: Hyper-parameters that older artifacts hold and that are no setting any more: dropped on load.
#: rnea_lq.filter_regressors: whether regressors meet the labels through the label filter is now
#: the dataset's preprocessing mode.
RETIRED_HYPERPARAMETERS: dict[str, tuple[str, ...]] = {'rnea_lq': ('filter_regressors',)}


def make_config(kind: str, **overrides: Any) -> ModelConfig:
    """The default config of a model kind, with overrides.

    Raises:
        ConfigError: unknown kind (lists the known ones), or a hyper-parameter unknown, of the
            wrong type or out of range (``hyper_schema.check_hyper``).
    """
    if kind not in MODEL_KINDS:
        raise ConfigError(f'unknown model kind {kind!r}; known kinds: {sorted(MODEL_KINDS)}')
    config_class = MODEL_KINDS[kind][0]
    return config_class(**{**check_hyper(kind, config_class, overrides), 'kind': kind})


def make_model(kind: str, robot: RobotConfig, **overrides: Any) -> InverseDynamicsModel:
    """An unfitted model of a kind for a robot."""
    config = make_config(kind, **overrides)
    return MODEL_KINDS[kind][1](config, robot)


def save_model(
    model: InverseDynamicsModel, folder: Path, extra: ArtifactExtra | None = None
) -> Path:
    """Write a fitted model as an artifact folder (safetensors + JSON)."""
    return write_artifact(
        Path(folder),
        model.kind,
        model.robot,
        model.state(),
        settings=model.config.to_dict(),
        fitted=model.fitted_metadata(),
        extra=extra,
    )


def load_model(
    folder: Path, robot: RobotConfig, kind: str | None = None, *, target: str | None = None
) -> InverseDynamicsModel:
    """Load and verify an artifact for a robot.

    ``target``: the torque the caller's data holds ('motor' or 'joint'; a run's
    ``preprocessing.target``); a model that predicts the other one is refused.

    Raises:
        CheckpointError: the folder is not a valid artifact of this robot (see read_artifact),
            or its model predicts another target than ``target``.
    """
    metadata, tensors = read_artifact(Path(folder), robot, kind)
    if target is not None and artifact_target(metadata) != target:
        raise CheckpointError(
            f'{folder}: its model.json says the model predicts the '
            f"{artifact_target(metadata)!r} torque, but the run's preprocessing.target is "
            f'{target!r}: the model does not belong to this run'
        )
    found = metadata['kind']
    if found not in MODEL_KINDS:
        raise CheckpointError(f'{folder}: unknown model kind {found!r}')
    retired = ('kind', *RETIRED_HYPERPARAMETERS.get(found, ()))
    hyper = metadata['hyperparameters']
    try:
        config = make_config(found, **{k: v for k, v in hyper.items() if k not in retired})
    except (ConfigError, TypeError) as err:
        raise CheckpointError(f'{folder}: hyper-parameters do not fit {found}: {err}') from err
    model = MODEL_KINDS[found][1](config, robot)
    model.load_state(tensors, metadata['fitted'])
    _check_period(model, metadata['robot'].get('ipo_period_s'), folder)
    return model


def _check_period(model: InverseDynamicsModel, trained_s: float | None, folder: Path) -> None:
    """Refuse a sequence model at another IPO period; warn for the others.

    A sequence model's window is a count of samples: at another rate it spans another time. The
    others are functions of (q, v, a), but their labels were filtered and their inputs smoothed
    at the training rate.

    Raises:
        CheckpointError: a sequence model trained at another period than the robot config's.
    """
    now_s = model.robot.ipo_period_s
    if trained_s is None or math.isclose(trained_s, now_s, rel_tol=1e-9):
        return
    text = (
        f'{folder}: trained on recordings at an IPO period of {trained_s * 1e3:g} ms; the robot '
        f'config says {now_s * 1e3:g} ms'
    )
    if as_sequence_model(model) is not None:
        raise CheckpointError(f'{text}: its window counts samples, so it would span another '
                              'time; retrain it on recordings at this period')  # fmt: skip
    _LOG.warning('%s: its labels were filtered and inputs smoothed at the other rate; compare '
                 'it on recordings at this period before trusting it', text)  # fmt: skip
