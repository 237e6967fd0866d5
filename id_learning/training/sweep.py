"""Hyper-parameter sweeps on Optuna: one study, as many worker processes as you start.

A trial draws a kind's hyper-parameters from its search space (``SEARCH_SPACES``), fits the model
on the training part of the bags and scores it on that part's validation tail (the last
``TrainingData.validation_fraction`` of it), through the label filter like every figure of the
package, as the mean normalised RMSE over joints. The test part stays unseen, so the test figure
of ``train --hyper-file DIR/best.yaml`` is honest. Networks report their validation loss every
epoch, and the median pruner stops trials that fall behind. The storage is any Optuna URL:
SQLite by default; PostgreSQL (``postgresql+psycopg://...``) lets workers on several machines
share one study. A study holds trials of one kind, target, robot, preprocessing and set of bags
(``study_settings``, recorded in the study): a worker with other settings is refused.
"""

from __future__ import annotations

import json
import logging
import math
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from id_learning.config_io import finite_number
from id_learning.dataset.preprocess import PreprocessConfig, Target
from id_learning.errors import ConfigError, IdLearningError
from id_learning.models.data import TrainingData
from id_learning.models.fitting import configure_torch
from id_learning.models.registry import MODEL_KINDS, make_model
from id_learning.models.torch_model import TorchModel
from id_learning.outputs import check_kind, check_target
from id_learning.robot.config import RobotConfig
from id_learning.training.datasets import combine_datasets, load_datasets
from id_learning.training.sweep_storage import check_sqlite_file

if TYPE_CHECKING:
    import optuna

__all__ = [
    'SEARCH_SPACES',
    'SETTINGS_ATTR',
    'SweepResult',
    'lost_schema_race',
    'run_sweep',
    'study_settings',
    'validation_error',
]

_LOG = logging.getLogger(__name__)

#: Tries to create or join a study while other workers create it too.
STORAGE_ATTEMPTS = 10
#: How long a worker waits for a busy (locked SQLite) or unreachable (PostgreSQL) storage [s],
#: per connection and for the retries of opening it together.
STORAGE_TIMEOUT_S = 10.0
# PostgreSQL's duplicate_table, duplicate_object and duplicate_schema: a schema race lost.
_DUPLICATE_SQLSTATES = frozenset({'42P07', '42710', '42P06'})
#: A hyper-parameter's range: ('log', low, high), ('int', low, high) or ('choice', options).
Space = tuple[Any, ...]

_NETWORK = {
    'learning_rate': ('log', 1e-4, 1e-2),
    'weight_decay': ('choice', (0.0, 1e-6, 1e-5, 1e-4, 1e-3)),
}
_MLP = {'width': ('choice', (32, 64, 128, 256)), 'depth': ('int', 1, 4), **_NETWORK}
_LAGRANGIAN = {
    **_MLP,
    'activation': ('choice', ('tanh', 'softplus')),
    'energy_balance': ('choice', (0.0, 0.5, 0.75, 1.0)),
    'lr_decay': ('choice', (1.0, 0.3)),
}

#: Per kind, the hyper-parameters a sweep draws and their ranges (the config's field names).
SEARCH_SPACES: dict[str, dict[str, Space]] = {
    'rnea_lq': {'friction': ('choice', ('viscous', 'viscous_coulomb', 'viscous_coulomb_offset'))},
    'rnea_mlp': _MLP,
    'delan': _LAGRANGIAN,
    'lnn': _LAGRANGIAN,
    'lnn_mlp': _LAGRANGIAN,
    'mlp': {**_MLP, 'activation': ('choice', ('tanh', 'relu'))},
    'lstm': {
        'hidden_size': ('choice', (32, 64, 128)),
        'num_layers': ('int', 1, 3),
        'sequence_length': ('choice', (10, 20, 40)),
        **_NETWORK,
    },
    'rnea_id': {
        'mass_rel_std': ('log', 0.02, 0.3),
        'com_std_m': ('log', 0.005, 0.1),
        'gain_std': ('log', 0.01, 0.2),
    },
    'rnea_id_mlp': _MLP,
    'delan_id': _LAGRANGIAN,
    'lnn_mlp_id': _LAGRANGIAN,
}


@dataclass(frozen=True)
class SweepResult:
    """What a worker leaves behind.

    Attributes:
        study_name: the Optuna study.
        storage: its storage URL.
        kind: the swept model kind.
        finished: trials of the study that completed (all workers).
        best_value: the best validation error (mean normalised RMSE).
        best_params: the best trial's hyper-parameters.
        best_file: DIR/best.yaml, which ``train --hyper-file`` reads.
        figures: the plots written (optimisation history, parameter importances).
    """

    study_name: str
    storage: str
    kind: str
    finished: int
    best_value: float
    best_params: dict[str, Any]
    best_file: Path
    figures: tuple[Path, ...]


def validation_error(model: Any, data: TrainingData) -> float:
    """Mean normalised RMSE over joints on the validation tail, the way the model was fitted.

    Through the filter, the torque along each whole recording on a controller's inputs,
    filtered like the labels; the study's way, the torque on its inputs as is.
    """
    from id_learning.evaluation.metrics import error_metrics
    from id_learning.evaluation.scoring import predict_along

    ds = data.dataset
    rows = data.validation_rows
    if ds.is_through_filter:
        torque = ds.filter_like_labels(predict_along(model, ds.controller, ds.recording_rows()))
    else:  # along each recording: a sequence model reads the samples before each row
        torque = predict_along(model, ds.study, ds.recording_rows())
    metrics = error_metrics(torque[rows], ds.tau[rows], ds.target_scaler.scale())
    return float(np.mean(metrics.rmse_normalised))


def _suggest(trial: optuna.Trial, name: str, space: Space) -> Any:
    kind = space[0]
    if kind == 'log':
        return trial.suggest_float(name, space[1], space[2], log=True)
    if kind == 'int':
        return trial.suggest_int(name, space[1], space[2])
    return trial.suggest_categorical(name, list(space[1]))


def _check_kind(kind: str) -> dict[str, Space]:
    if kind not in MODEL_KINDS:
        raise ConfigError(f'sweep: unknown model kind {kind!r}; known: {sorted(MODEL_KINDS)}')
    if kind not in SEARCH_SPACES:
        raise ConfigError(
            f'sweep: {kind!r} has no search space (its settings come from a diagnosis); '
            f'sweepable: {sorted(SEARCH_SPACES)}'
        )
    return SEARCH_SPACES[kind]


def run_sweep(
    bags: Sequence[Path],
    robot: RobotConfig,
    target: Target,
    kind: str,
    out: Path,
    *,
    trials: int,
    storage: str | None = None,
    study_name: str | None = None,
    max_seconds_per_trial: float | None = None,
    preprocess: PreprocessConfig | None = None,
    progress: bool = True,
    seed: int | None = None,
    trim_unpaired_tail: bool = False,
    storage_timeout_s: float = STORAGE_TIMEOUT_S,
) -> SweepResult:
    """Run ``trials`` trials of one kind into a (possibly shared) study; write DIR/best.yaml.

    ``storage_timeout_s`` bounds the wait for a locked or unreachable storage, when opening it
    and at each later access.

    The study records what its trials are run on (``study_settings``: kind, target, robot, the
    bags' SHA-256, preprocessing) when it is made; a study that records other settings is
    refused, so that its best trial is always one of this kind on this data.

    Raises:
        ConfigError: unknown or unsweepable kind, trials < 1, a bad timeout or budget, an
            unusable, locked or unreachable storage (names it), or a study of other settings
            (names both); ``out`` holds other than a sweep (``OutputError``: another
            command's result is never written into).
        DatasetError, BagError: a bag is unusable, or a trial's fit fails on it (one line
            naming the trial; Optuna's own report of the failure is left out).
    """
    import optuna
    from sqlalchemy.exc import SQLAlchemyError

    space = _check_kind(kind)
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ConfigError(f'sweep: --trials must be >= 1, got {trials}')
    finite_number(storage_timeout_s, 'sweep: storage timeout [s]', low=0, high=3600, low_open=True)
    if max_seconds_per_trial is not None:
        finite_number(
            max_seconds_per_trial, 'sweep: --max-seconds-per-trial', low=0, low_open=True
        )
    # The folder is added to by every worker: it must be empty or a sweep's, and no input's.
    out = check_target(Path(out), inputs=[Path(b) for b in bags])
    check_kind(out, 'sweep', force=False)
    out.mkdir(parents=True, exist_ok=True)
    storage = storage or f'sqlite:///{(out / "sweep.db").resolve()}'
    study_name = study_name or f'{kind}-{target}'
    config = PreprocessConfig(target=target) if preprocess is None else preprocess
    # The storage first: a locked or unreachable one is refused before the bags are read.
    study = _open_study(storage, study_name, seed, storage_timeout_s)
    datasets = load_datasets(
        [Path(b) for b in bags],
        robot,
        config,
        progress=progress,
        trim_unpaired_tail=trim_unpaired_tail,
    )
    # Before any trial: a study of another kind, data, target or robot is refused.
    settings = study_settings(kind, target, robot, bags, config)
    _claim_study(study, settings, storage)
    data = TrainingData(combine_datasets(datasets), robot)
    configure_torch(1)
    names = {f.name for f in fields(make_model(kind, robot).config)}

    def objective(trial: optuna.Trial) -> float:
        _claim_study(study, settings, storage)  # a worker that raced this one to the study
        params = {name: _suggest(trial, name, s) for name, s in space.items() if name in names}
        if max_seconds_per_trial is not None and 'max_seconds' in names:
            params['max_seconds'] = max_seconds_per_trial
        if 'device' in names:
            params['device'] = 'cpu'
        model = make_model(kind, robot, **params)
        if isinstance(model, TorchModel):

            def report(epoch: int, loss: float) -> bool:
                trial.report(loss, epoch)
                return trial.should_prune()

            model.epoch_hook = report
        model.fit(data)
        history = model.history_ if isinstance(model, TorchModel) else None
        if history is not None and history.stopped_by == 'pruned':
            raise optuna.TrialPruned()
        return validation_error(model, data)

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        with _failed_trials_said_once() as said:
            study.optimize(said(objective), n_trials=trials, show_progress_bar=progress)
        complete = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    except SQLAlchemyError as err:  # locked or gone after it was opened
        raise ConfigError(f'sweep: the storage {storage!r} failed: {_reason(err)}') from err
    if not complete:
        raise ConfigError(f'sweep: no trial of study {study_name!r} completed')
    best = study.best_trial
    params = dict(best.params)
    value = float(best.value) if best.value is not None else float('nan')
    best_file = out / 'best.yaml'
    best_file.write_text(
        yaml.safe_dump({kind: params}, sort_keys=True)
        + f'# study {study_name}: validation error {value:.6g} '
        f"(mean normalised RMSE on the training part's validation tail), trial {best.number}\n",
        encoding='utf-8',
    )
    return SweepResult(
        study_name=study_name,
        storage=storage,
        kind=kind,
        finished=len(complete),
        best_value=value,
        best_params=params,
        best_file=best_file,
        figures=_plots(study, out),
    )


#: The study's user attribute that records what its trials are run on (``study_settings``).
SETTINGS_ATTR = 'id_learning.sweep'


def study_settings(
    kind: str,
    target: str,
    robot: RobotConfig,
    bags: Sequence[Path],
    preprocess: PreprocessConfig,
) -> dict[str, Any]:
    """What a study's trials must share to be compared: kind, target, robot, data, preprocessing.

    Trials fitted on other bags, for another target or robot, or preprocessed otherwise score
    on another validation part; trials of another kind hold other hyper-parameters (best.yaml
    would give one kind's under another's name). JSON-ready (a study's user attribute).
    """
    from id_learning.models.artifact import robot_fingerprint
    from id_learning.training.datasets import bag_sha256

    fingerprint = robot_fingerprint(robot)
    settings = {
        'kind': kind,
        'target': target,
        'robot': {key: fingerprint[key] for key in ('name', 'joints', 'urdf_sha256')},
        'bags_sha256': [bag_sha256(Path(bag)) for bag in bags],
        'preprocessing': {k: v for k, v in asdict(preprocess).items() if k != 'target'},
    }
    normalised: dict[str, Any] = json.loads(json.dumps(settings))  # tuples as lists
    return normalised


#: How ``_claim_study`` names each setting.
_SETTING_LABELS = {'kind': 'model kind', 'bags_sha256': 'bags'}


def _shown(key: str, value: Any) -> str:
    if key == 'robot' and isinstance(value, dict):
        return f'{value.get("name")!r} (URDF {str(value.get("urdf_sha256"))[:12]})'
    if key == 'bags_sha256' and isinstance(value, list):
        return '[' + ', '.join(f'SHA-256 {str(sha)[:12]}' for sha in value) + ']'
    return repr(value)


def _claim_study(study: optuna.Study, settings: dict[str, Any], storage: str) -> None:
    """Record ``settings`` in a new study; refuse a study recorded with others.

    Raises:
        ConfigError: the study records other settings (names the first that differs, both
            values), or holds trials without a record (made before sweeps recorded one).
    """
    saved = study.user_attrs.get(SETTINGS_ATTR)
    if saved is None:
        held = len(study.get_trials(deepcopy=False))
        if held:
            raise ConfigError(
                f'sweep: study {study.study_name!r} in {storage!r} holds {held} trial(s) but '
                'no record of the kind, data and target they were run on (made before sweeps '
                "recorded them): they cannot be told from this sweep's; name another "
                '--study-name'
            )
        study.set_user_attr(SETTINGS_ATTR, settings)
        saved = study.user_attrs.get(SETTINGS_ATTR)  # a worker starting with this one may win
    for key, value in settings.items():
        theirs, ours = (saved.get(key) if isinstance(saved, dict) else None), value
        if theirs == ours:
            continue
        if isinstance(theirs, dict) and isinstance(ours, dict):  # the items that differ
            keys = [k for k in {**theirs, **ours} if theirs.get(k) != ours.get(k)]
            theirs, ours = ({k: d.get(k) for k in keys} for d in (theirs, ours))
        label = _SETTING_LABELS.get(key, key)
        raise ConfigError(
            f'sweep: study {study.study_name!r} in {storage!r} holds trials for {label} '
            f'{_shown(key, theirs)}; this sweep is for {_shown(key, ours)}: a study compares '
            'trials of one kind, target, robot, preprocessing and data; name another '
            '--study-name'
        )


@contextmanager
def _failed_trials_said_once() -> Iterator[Callable[[Callable[..., float]], Callable[..., float]]]:
    """Say a failed trial once: as the error the sweep raises, without Optuna's traceback.

    Optuna logs a trial that raised (the exception and its traceback) and then raises it
    again; the sweep names the trial in the error instead (a package error is one line, a bug
    keeps its one traceback). Yields the wrapper of the objective that does so.
    """
    failed: set[int] = set()

    class _Filter(logging.Filter):
        def filter(self, record: logging.LogRecord) -> bool:
            text = record.getMessage()
            return not any(text.startswith(f'Trial {number} failed') for number in failed)

    def said(objective: Callable[[optuna.Trial], float]) -> Callable[[optuna.Trial], float]:
        def wrapped(trial: optuna.Trial) -> float:
            try:
                return objective(trial)
            except IdLearningError as err:
                failed.add(trial.number)
                if str(err).startswith('sweep:'):  # says what failed already
                    raise
                raise type(err)(f'sweep: trial {trial.number} failed: {err}') from err
            except Exception:
                failed.add(trial.number)
                raise

        return wrapped

    logger, only = logging.getLogger('optuna.study._optimize'), _Filter()
    logger.addFilter(only)
    try:
        yield said
    finally:
        logger.removeFilter(only)


def _engine_options(storage: str, timeout_s: float) -> dict[str, Any]:
    """SQLAlchemy engine options that bound the wait for a busy or unreachable storage."""
    if storage.startswith('sqlite'):
        # Wait for a busy database (several local workers), but not for ever.
        return {'connect_args': {'timeout': timeout_s}}
    if storage.startswith('postgresql'):
        # libpq's connect_timeout is whole seconds (at least 2 are honoured).
        return {'connect_args': {'connect_timeout': max(2, math.ceil(timeout_s))}}
    return {}


def _reason(err: Exception) -> str:
    """The driver's one-line reason behind a SQLAlchemy error (without its SQL and links)."""
    text = str(getattr(err, 'orig', None) or err)
    return text.strip().splitlines()[0] if text.strip() else type(err).__name__


def _open_study(
    storage: str, study_name: str, seed: int | None, timeout_s: float = STORAGE_TIMEOUT_S
) -> optuna.Study:
    """Create or join the study; workers starting together race to create the schema.

    A lost race is retried until ``timeout_s`` has passed; a storage still locked or
    unreachable then is refused.

    Raises:
        ConfigError: the storage cannot be opened (names the URL and the reason).
    """
    import optuna
    from sqlalchemy.exc import SQLAlchemyError

    check_sqlite_file(storage, timeout_s)
    engine = _engine_options(storage, timeout_s)
    deadline = time.monotonic() + timeout_s
    last: Exception | None = None
    for attempt in range(STORAGE_ATTEMPTS):
        try:
            optuna.logging.set_verbosity(optuna.logging.WARNING)  # its own INFO lines, too
            return optuna.create_study(
                study_name=study_name,
                storage=optuna.storages.RDBStorage(storage, engine_kwargs=engine),
                load_if_exists=True,
                direction='minimize',
                sampler=optuna.samplers.TPESampler(seed=seed),
                pruner=optuna.pruners.MedianPruner(n_startup_trials=2, n_warmup_steps=5),
            )
        except SQLAlchemyError as err:
            if not lost_schema_race(err):
                raise ConfigError(
                    f'sweep: cannot open the storage {storage!r}: {_reason(err)}'
                ) from err
            last = err
            if time.monotonic() >= deadline:
                break
            time.sleep(0.2 * (attempt + 1))
        except (
            ValueError,
            ImportError,
            optuna.exceptions.StorageInternalError,
        ) as err:
            raise ConfigError(f'sweep: cannot open the storage {storage!r}: {err}') from err
    reason = _reason(last) if last is not None else 'no answer'
    raise ConfigError(
        f'sweep: cannot open the storage {storage!r} within {timeout_s:g} s ({reason}): another '
        'process may hold it locked, or the server is unreachable'
    )


def lost_schema_race(err: Exception) -> bool:
    """Whether opening the storage failed because another worker created the schema first.

    Workers that start together on a fresh database both find a table missing and both create
    it; the later one fails with a duplicate (table, object or key) or a locked database.
    Retrying then finds the schema in place. Every OperationalError counts (a database that is
    busy or still starting), so an unreachable server is reported after the retries.
    """
    from sqlalchemy.exc import IntegrityError, OperationalError, ProgrammingError

    if isinstance(err, IntegrityError | OperationalError):
        return True
    return isinstance(err, ProgrammingError) and _sqlstate(err) in _DUPLICATE_SQLSTATES


def _sqlstate(err: Exception) -> str | None:
    """The database's SQLSTATE code behind a SQLAlchemy error, where the driver gives one."""
    orig = getattr(err, 'orig', None)
    code = getattr(orig, 'sqlstate', None) or getattr(orig, 'pgcode', None)
    return code if isinstance(code, str) else None


def _plots(study: optuna.Study, out: Path) -> tuple[Path, ...]:
    """The optimisation history and, with enough trials, the parameter importances."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import optuna
    from optuna.exceptions import ExperimentalWarning
    from optuna.visualization import matplotlib as optuna_plots

    complete = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    settings = {json.dumps(t.params, sort_keys=True, default=str) for t in complete}
    plots: list[tuple[str, Any]] = [
        ('optimisation_history.png', optuna_plots.plot_optimization_history)
    ]
    if len(settings) > 1:  # importances compare trials of different settings
        plots.append(('parameter_importances.png', optuna_plots.plot_param_importances))
    else:
        _LOG.info('sweep: no parameter importances from %d distinct setting(s)', len(settings))
    written = []
    for name, draw in plots:
        try:
            with warnings.catch_warnings():  # optuna's matplotlib plots are 'experimental'
                warnings.simplefilter('ignore', ExperimentalWarning)
                axes = draw(study)
        except (ValueError, RuntimeError) as err:  # importances need >= 2 finished trials
            _LOG.info('sweep: no %s (%s)', name, err)
            continue
        figure = axes.get_figure(root=True)
        assert figure is not None
        figure.savefig(out / name, dpi=110, bbox_inches='tight')
        plt.close(figure)
        written.append(out / name)
    return tuple(written)
