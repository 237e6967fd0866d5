"""The diagnosis of a training set's training part, for the models built on its effects."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from id_learning.dataset.preprocess import Dataset
from id_learning.diagnosis.config import DiagnosisConfig
from id_learning.diagnosis.pipeline import run_diagnosis
from id_learning.errors import ConfigError, DatasetError
from id_learning.physics.augmented import AugmentedModel
from id_learning.robot.config import RobotConfig

__all__ = ['diagnose_training_part', 'training_part']


def training_part(dataset: Dataset, config: DiagnosisConfig | None = None) -> Dataset:
    """The training part as a dataset of its own, split like a recording the diagnosis reads.

    The diagnosis holds out the training part's tail (``config.preprocess.train_fraction`` of
    it, 30 % by default) to check that an effect improves data the fit did not see; the test
    part stays unseen. Each recording's training part stays one segment, so filters never cross
    the seam between two recordings.
    """
    if dataset.is_shuffled:
        raise ConfigError(
            'the diagnosis reads the training part as a stretch in time: it needs '
            '--split contiguous (a shuffled split scatters the training samples)'
        )
    config = config or DiagnosisConfig()
    rows = slice(0, dataset.n_train)
    n_train = round(config.preprocess.train_fraction * dataset.n_train)
    segments = [
        {'source': s.get('source', ''), 'train': s['train'], 'test': [s['train'][1]] * 2}
        for s in dataset.extra.get('segments', [])
    ]
    return replace(
        dataset,
        stamps_ns=dataset.stamps_ns[rows],
        q=dataset.q[rows],
        v=dataset.v[rows],
        a=dataset.a[rows],
        tau=dataset.tau[rows],
        tau_raw=dataset.tau_raw[rows],
        n_train=n_train,
        controller=dataset.controller.take(rows),
        study=dataset.study.take(rows),
        tau_clean=None if dataset.tau_clean is None else dataset.tau_clean[rows],
        extra={'segments': segments} if segments else {},
    )


def diagnose_training_part(
    dataset: Dataset, robot: RobotConfig, config: DiagnosisConfig | None = None
) -> tuple[AugmentedModel, dict[str, Any]]:
    """Diagnose the training part; the augmented model and a JSON-ready summary of the finding."""
    config = config or DiagnosisConfig()
    try:
        result = run_diagnosis(training_part(dataset, config), robot, config)
    except DatasetError as err:  # its lengths are the training part's, not the recordings'
        share = dataset.n_train / max(len(dataset.q), 1)
        raise DatasetError(
            f'{err}; these lengths are of the training part only ({share:.0%} of the '
            f'recordings): the recordings need about {1 / max(share, 1e-9):.2g} times as long'
        ) from err
    summary = {
        'source': 'diagnosis of the training part (its last 30 % held out)',
        'effects': [effect.label for effect in result.named_effects()],
        'alias_sets': [list(alias.members) for alias in result.alias_sets],
        'untestable': [list(item) for item in result.untestable_effects()],
        'cut_short': list(result.cut_short),
    }
    return result.augmented_model, summary
