"""Fitting the models of a run: per-kind settings, the shared diagnosis, and the fits.

``train_run`` checks every kind's settings before any bag is loaded (``resolve_overrides``), then
fits the kinds one after the other on the same training data (``fit_models``). Evaluating the
fitted models is ``training.measure``'s; writing them is ``training.run_folder``'s.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from id_learning.errors import ConfigError, IdLearningError
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.data import DiagnosedEffects, TrainingData
from id_learning.models.fitting import select_device
from id_learning.robot.config import RobotConfig

__all__ = [
    'FIT_ORDER',
    'TRAIN_THREADS',
    'ModelResult',
    'cut_short',
    'fit_models',
    'fit_order',
    'model_overrides',
    'resolve_overrides',
]

TRAIN_THREADS = 1  # torch intra-op threads for fitting and evaluating the small networks

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ModelResult:
    """One fitted (or loaded) model of a run and its numbers.

    Attributes:
        kind: registry name.
        model: the fitted model.
        folder: its artifact folder.
        metrics: the metrics.json entry (errors, timings, training summary).
    """

    kind: str
    model: InverseDynamicsModel
    folder: Path
    metrics: dict[str, Any]


def model_overrides(
    kind: str,
    hyper: dict[str, dict[str, Any]],
    *,
    max_seconds: float | None = None,
    device: str = 'auto',
) -> dict[str, Any]:
    """The hyper-parameter overrides of one kind: the user's, a time budget and the device."""
    from id_learning.models.registry import MODEL_KINDS

    if kind not in MODEL_KINDS:
        raise ConfigError(f'unknown model kind {kind!r}; known kinds: {sorted(MODEL_KINDS)}')
    names = {item.name for item in fields(MODEL_KINDS[kind][0])}
    overrides = dict(hyper.get(kind, {}))
    # Settings a kind does not have (RNEA+LQ is a least-squares fit: no budget, no device) are
    # left out rather than refused: they are run-wide, not the user's per-kind choice.
    if max_seconds is not None and 'max_seconds' in names:
        overrides.setdefault('max_seconds', max_seconds)
    if 'device' in names:
        overrides.setdefault('device', device)
    return overrides


def cut_short(model: InverseDynamicsModel, history: dict[str, Any] | None) -> list[str]:
    """What the fit's time budget left out: epochs, identification or diagnosis steps."""
    out = []
    if history is not None and history.get('stopped_by') == 'time_budget':
        out.append('training stopped at its time budget')
    physics = getattr(model, 'physics_', None)
    out += list(getattr(physics, 'report', {}).get('cut_short', []))
    diagnosis = getattr(model, 'diagnosis_', None) or {}
    out += [f'diagnosis: {step}' for step in diagnosis.get('cut_short', [])]
    return out


def _history(model: InverseDynamicsModel) -> dict[str, Any] | None:
    for name in ('history_', 'train_history_'):
        history = getattr(model, name, None)
        if history is not None:
            return history.to_dict() if hasattr(history, 'to_dict') else dict(history)
    return None


#: The order kinds are fitted in, cheapest first, so that a run saves its fast models before
#: the slow ones start: least squares, the identification, the diagnosis, then the networks
#: (on physics first). Kinds not listed come last, in the order given.
FIT_ORDER = (
    'rnea_lq',
    'rnea_id',
    'rnea_effects',
    'rnea_id_mlp',
    'rnea_mlp',
    'rnea_effects_mlp',
    'mlp',
    'lstm',
    'delan_id',
    'delan',
    'lnn',
    'lnn_mlp_id',
    'lnn_mlp',
)


def fit_order(kinds: Sequence[str]) -> list[str]:
    """``kinds`` in the order they are fitted (``FIT_ORDER``); the report keeps the given order."""
    rank = {kind: k for k, kind in enumerate(FIT_ORDER)}
    return sorted(kinds, key=lambda kind: rank.get(kind, len(FIT_ORDER)))


def _diagnosis_users(kinds: Sequence[str], overrides: dict[str, dict[str, Any]]) -> list[str]:
    """The kinds that build on the diagnosis of the training part (no effects file given)."""
    from id_learning.models.registry import make_config

    return [k for k in kinds if getattr(make_config(k, **overrides[k]), 'effects', None) == '']


def _with_diagnosis(
    data: TrainingData, users: Sequence[str], max_seconds: float | None
) -> tuple[TrainingData, float, str | None]:
    """Diagnose the training part for the kinds that build on its effects, within a budget.

    Returns:
        The training data with the diagnosis, the seconds it took, and why it failed (None when
        it did not; the kinds that build on it cannot be fitted then).
    """
    from id_learning.diagnosis import DiagnosisConfig, diagnose_training_part

    start = time.perf_counter()
    try:
        model, summary = diagnose_training_part(
            data.dataset, data.robot, DiagnosisConfig(max_seconds=max_seconds)
        )
    except Exception as err:  # the other kinds do not need it: they go on
        reason = f'the diagnosis of the training part failed: {type(err).__name__}: {err}'
        expected = isinstance(err, IdLearningError)  # a stated reason needs no traceback
        _LOG.error('%s; not fitted: %s', reason, ', '.join(users), exc_info=not expected)
        return data, 0.0, reason
    seconds = time.perf_counter() - start
    _LOG.info('diagnosed the training part in %.1f s for %s', seconds, list(users))
    return replace(data, diagnosed=DiagnosedEffects(model, summary)), seconds, None


def resolve_overrides(
    kinds: Sequence[str],
    hyper: dict[str, dict[str, Any]],
    *,
    max_seconds: float | None,
    device: str,
) -> tuple[str, dict[str, dict[str, Any]]]:
    """The device to fit on, and per kind its overrides (``model_overrides``), each checked.

    Raises:
        ConfigError: hyper-parameters for a kind not in ``kinds``, an unavailable device, an
            unknown kind or an unknown hyper-parameter; refused before any bag is loaded.
    """
    from id_learning.models.registry import MODEL_KINDS, make_config

    unknown = sorted(set(hyper) - set(MODEL_KINDS))
    if unknown:
        raise ConfigError(
            f'hyper-parameters given for unknown model kind(s) {unknown}; '
            f'known kinds: {sorted(MODEL_KINDS)}'
        )
    untrained = sorted(set(hyper) - set(kinds))
    if untrained:
        raise ConfigError(f'hyper-parameters given for kinds that are not trained: {untrained}')
    resolved_device = str(select_device(device))
    overrides = {
        kind: model_overrides(kind, hyper, max_seconds=max_seconds, device=resolved_device)
        for kind in kinds
    }
    for kind in kinds:  # refuse a bad hyper-parameter before hours of loading and fitting
        make_config(kind, **overrides[kind])
    return resolved_device, overrides


def fit_models(
    data: TrainingData,
    robot: RobotConfig,
    kinds: Sequence[str],
    overrides: dict[str, dict[str, Any]],
    models_dir: Path,
    *,
    progress: bool,
    on_fitted: Callable[[ModelResult], None] | None = None,
) -> tuple[dict[str, ModelResult], dict[str, str]]:
    """Fit each kind on ``data``, cheapest first (``fit_order``); folders ``models_dir / kind``.

    A kind whose fit fails is skipped, with the reason; the others go on (hours of fitting are
    not lost to one model). ``on_fitted`` is called with each result as soon as it is fitted
    (the trainer saves it then). The diagnosis of the training part runs when the first kind
    that builds on it is due, within that kind's budget (``max_seconds``), and counts in its
    ``train_seconds``.

    Returns:
        The fitted models by kind (in the order of ``kinds``), and the failed kinds with why.
    """
    from id_learning.models.registry import make_model

    users = _diagnosis_users(kinds, overrides)
    diagnosis_seconds: dict[str, float] = {}
    failures: dict[str, str] = {}
    results: dict[str, ModelResult] = {}
    for kind in tqdm(fit_order(kinds), desc='models', unit='model', disable=not progress):
        if kind in users and data.diagnosed is None and not failures.keys() & set(users):
            budget = overrides[kind].get('max_seconds')
            data, seconds, failed = _with_diagnosis(data, users, budget)
            if failed is not None:
                failures.update(dict.fromkeys(users, failed))
            diagnosis_seconds = dict.fromkeys(users, seconds)
        if kind in failures:
            continue
        _LOG.info('fitting %s on %d samples', kind, data.n_fit)
        start = time.perf_counter()
        try:
            model = make_model(kind, robot, **overrides[kind])
            model.fit(data, progress=progress)
        except Exception as err:  # reported with the run; the other kinds go on
            failures[kind] = f'{type(err).__name__}: {err}'
            _LOG.error(
                '%s failed, the other models go on: %s',
                kind,
                failures[kind],
                exc_info=not isinstance(err, IdLearningError),
            )
            continue
        # A kind built on the diagnosis of the training part pays for it too.
        seconds = time.perf_counter() - start + diagnosis_seconds.get(kind, 0.0)
        history = _history(model)
        results[kind] = ModelResult(
            kind,
            model,
            models_dir / kind,
            {'train_seconds': seconds, 'history': history, 'cut_short': cut_short(model, history)},
        )
        _LOG.info('%s fitted in %.1f s', kind, seconds)
        if on_fitted is not None:
            on_fitted(results[kind])
    return {kind: results[kind] for kind in kinds if kind in results}, failures
