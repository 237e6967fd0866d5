"""The run folder on disk: its file names, run.json, metrics.json and the model artifacts.

Everything a run writes or reads back goes through here, so the documents' formats and keys are
defined in one place; ``training.trainer`` decides what goes into them. The layout is in
``training.trainer``'s docstring.
"""

from __future__ import annotations

import json
import logging
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from id_learning.config_io import broken_link, not_a_file, read_capped, short_json
from id_learning.dataset.preprocess import Dataset, MinMaxScaler
from id_learning.errors import CheckpointError
from id_learning.models.artifact import (
    ARTIFACT_HASH,
    METADATA_FILE,
    _git_commit,
    read_metadata,
    robot_fingerprint,
)
from id_learning.models.base import InverseDynamicsModel
from id_learning.models.metadata_checks import DuplicateKeyError, loads_unique
from id_learning.outputs import incomplete_reason, partial_path, write_text_atomic
from id_learning.robot.config import RobotConfig
from id_learning.training.datasets import Samples, bag_sha256, refuse_shared_samples
from id_learning.training.fitting import ModelResult
from id_learning.training.measure import metric_notes

__all__ = [
    'ARTIFACTS_KEY',
    'METRICS_FILE',
    'METRICS_FORMAT',
    'MODELS_DIR',
    'REPORT_FILE',
    'RUN_FILE',
    'RUN_FORMAT',
    'check_run_model',
    'is_training_bag',
    'load_run_model',
    'machine_info',
    'metrics_document',
    'read_run',
    'refuse_incomplete_run',
    'refuse_training_samples',
    'run_document',
    'save_models',
    'training_bag',
    'write_json',
]

_LOG = logging.getLogger(__name__)

RUN_FORMAT = 'id_learning.run/1'
METRICS_FORMAT = 'id_learning.metrics/1'
RUN_FILE = 'run.json'
METRICS_FILE = 'metrics.json'
REPORT_FILE = 'report.md'
MODELS_DIR = 'models'
#: The largest run.json read [bytes]: the run's settings, its bags and machine are a few KiB;
#: a file of megabytes is no run document (and read whole it could fill the memory).
MAX_RUN_DOCUMENT_BYTES = 16 * 2**20


def machine_info() -> dict[str, Any]:
    """The machine the numbers were measured on: host, processor, torch and its threads, GPU."""
    return {
        'host': platform.node(),
        'processor': platform.processor() or platform.machine(),
        'cpu_count': os.cpu_count(),
        'torch': torch.__version__,
        'torch_threads': torch.get_num_threads(),
        'cuda': torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }


def write_json(path: Path, document: dict[str, Any]) -> None:
    """Write ``document`` as indented JSON with a final newline, whole or not at all."""
    write_text_atomic(path, json.dumps(document, indent=1) + '\n')


def _models_held(run_dir: Path, document: dict[str, Any] | None) -> str:
    """'holds 2 of 7 models' of a run folder, from its run.json, else from its models/."""
    requested = (document or {}).get('requested_kinds')
    saved = (document or {}).get('kinds')
    if not isinstance(saved, list):
        folder = run_dir / MODELS_DIR
        saved = (
            [p for p in folder.iterdir() if (p / 'model.json').is_file()]
            if folder.is_dir()
            else []
        )
    of = f' of {len(requested)}' if isinstance(requested, list) else ''
    return f'it holds {len(saved)}{of} model(s)'


def _run_text(path: Path) -> str:
    """A run's run.json as text: a regular file of at most ``MAX_RUN_DOCUMENT_BYTES``.

    The run folder is ours: a FIFO there (which nobody may ever write) or a device is refused
    at once, naming the file and what it is, instead of blocking or reading without end.

    Raises:
        CheckpointError: missing, no regular file, over the cap, or not UTF-8; names the file.
    """
    data = read_capped(
        path, 'run document', MAX_RUN_DOCUMENT_BYTES, regular=True, error=CheckpointError
    )
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise CheckpointError(f'{path}: not valid JSON: {err}') from err


def _read_document(path: Path) -> dict[str, Any] | None:
    try:
        document = loads_unique(_run_text(path))
    except (CheckpointError, ValueError):  # a key given twice too: read_run names it
        return None
    return document if isinstance(document, dict) else None


def refuse_incomplete_run(run_dir: Path) -> None:
    """Refuse a run folder a ``train`` did not finish (killed, failed, or still running).

    Incomplete: ``<run>.partial`` (or ``<run>`` absent while that exists), the incomplete marker,
    or a run.json whose status says so (or, written before the status, without metrics.json).

    Raises:
        CheckpointError: names the folder, what it holds, and that a new train replaces it.
    """
    run_dir = Path(run_dir)
    reason = incomplete_reason(run_dir)
    holder = partial_path(run_dir) if not run_dir.exists() else run_dir
    document = _read_document(holder / RUN_FILE)
    if reason is None and document is not None and document.get('format') == RUN_FORMAT:
        status = document.get('status')
        if status not in (None, 'incomplete', 'complete'):
            raise CheckpointError(
                f'{run_dir}: {RUN_FILE} says status {status!r}; a run is complete or '
                'incomplete (edited by hand?): a new train with --force writes a whole one'
            )
        if status == 'incomplete' or (status is None and not (holder / METRICS_FILE).is_file()):
            reason = f'{run_dir}: an incomplete training run ({RUN_FILE} says so)'
    if reason is not None:
        raise CheckpointError(
            f'{reason}; {_models_held(holder, document)}, and part of a run would pass for the '
            'whole: a new train with --force replaces it'
        )


def read_run(run_dir: Path) -> dict[str, Any]:
    """Read a complete run folder's run.json.

    Raises:
        CheckpointError: missing, no regular file (a FIFO, a device: named), over
            ``MAX_RUN_DOCUMENT_BYTES``, not JSON, a key given twice, not a run document, or an
            incomplete run.
    """
    kind = not_a_file(run_dir)
    if kind not in (None, 'a folder', 'no such file'):
        raise CheckpointError(f'{run_dir}: {kind}, not a training run folder (train writes one)')
    path = Path(run_dir) / RUN_FILE
    link = broken_link(path)
    if link is not None:
        raise CheckpointError(
            f'{path}: {link}: the run document is not where the link points; restore it, or '
            'copy the run folder whole instead of linking its files'
        )
    refuse_incomplete_run(run_dir)
    if not path.exists():
        raise CheckpointError(f'{run_dir}: not a training run folder (no {RUN_FILE})')
    try:
        document = loads_unique(_run_text(path))
    except DuplicateKeyError as err:
        raise CheckpointError(f'{path}: {err}; the file was edited or is corrupt') from err
    except json.JSONDecodeError as err:
        raise CheckpointError(f'{path}: not valid JSON: {err}') from err
    if not isinstance(document, dict) or document.get('format') != RUN_FORMAT:
        raise CheckpointError(f'{path}: format is not {RUN_FORMAT!r}')
    return document


#: run.json's key of each model's ``artifact_sha256`` as the run saved it.
ARTIFACTS_KEY = 'artifacts'


def load_run_model(
    run_dir: Path, run: dict[str, Any], kind: str, robot: RobotConfig
) -> InverseDynamicsModel:
    """A run's model of ``kind``, verified to be the one the run trained and saved.

    Raises:
        CheckpointError: the artifact is invalid (``load_model``), of another target, or not
            the model this run saved (``check_run_model``).
    """
    from id_learning.models.registry import load_model

    folder = Path(run_dir) / MODELS_DIR / kind
    target = (run.get('preprocessing') or {}).get('target')
    model = load_model(folder, robot, kind, target=target)
    check_run_model(folder, run)
    return model


def check_run_model(folder: Path, run: dict[str, Any] | None = None) -> None:
    """Refuse a model in a run's ``models/`` that is not the one the run saved there.

    A model folder is self-consistent wherever it came from; run.json records each model's
    ``artifact_sha256``, so another run's model copied or linked into ``models/`` is refused
    instead of being scored or tracked as this run's (the predictor node warns of it). A folder
    outside a run passes unchecked, and a run from before the record is checked only as below.
    ``run``: the run's run.json, when read already.

    run.json itself holds no hash (it is rewritten as the run goes on, and a hash written
    again after an edit proves nothing): what it shares with each model's model.json
    (``SHARED_SECTIONS``) must say the same, since model.json is hash-checked and is the one
    run.json records. A hand edit of run.json (a gear ratio, the scaler, the target) would
    otherwise change what ``evaluate`` reads without a word.

    Raises:
        CheckpointError: the run is incomplete or unreadable (``read_run``), the model's
            model.json is not the one run.json records (names both digests' starts), or
            run.json differs from it in a shared section (names run.json, the key and both
            values).
    """
    folder = Path(folder)
    run_dir = folder.parent.parent
    if folder.parent.name != MODELS_DIR or not os.path.lexists(run_dir / RUN_FILE):
        return  # a model outside a run (a folder that happens to be called models)
    run = run if run is not None else read_run(run_dir)
    recorded = (run.get(ARTIFACTS_KEY) or {}).get(folder.name)
    meta_path = folder / METADATA_FILE
    if recorded is None and not meta_path.is_file():
        return  # nothing recorded, nothing to compare with: loading the model names the fault
    metadata = read_metadata(meta_path)
    held = metadata.get(ARTIFACT_HASH)
    if recorded is not None and held != recorded:
        raise CheckpointError(
            f'{folder}: not the {folder.name} model this run trained: its model.json '
            f'({ARTIFACT_HASH} {str(held)[:12]}...) differs from the one {RUN_FILE} records '
            f'({str(recorded)[:12]}...), so it was copied or linked in from another run; copy '
            'a run whole, or train again'
        )
    _refuse_edited_run(run_dir / RUN_FILE, run, meta_path, metadata, saved=recorded is not None)


#: The sections run.json shares with each of its models' model.json (``save_models`` writes
#: them into both): the robot the run was for, and what ``evaluate`` reads back.
SHARED_SECTIONS = ('robot', 'preprocessing', 'target_scaler', 'training_data')
_ABSENT = object()


def _refuse_edited_run(
    run_file: Path, run: dict[str, Any], meta_path: Path, metadata: dict[str, Any], *, saved: bool
) -> None:
    """Refuse a run.json whose shared sections differ from a model's model.json.

    A section that one of the two lacks (written before it existed) is not compared. ``saved``:
    the model is the one run.json records, so the edit was made in run.json.

    Raises:
        CheckpointError: names run.json, the first key that differs, both values and model.json.
    """
    for section in SHARED_SECTIONS:
        if section not in run or section not in metadata:
            continue
        found = _first_difference(run[section], metadata[section], section)
        if found is None:
            continue
        key, ours, theirs = found
        why = (
            f'the model the run saved (its {ARTIFACT_HASH} is the one {RUN_FILE} records), '
            f'so {RUN_FILE} was edited after the run; restore it, or train again'
            if saved
            else f'the model in this run: {RUN_FILE} or the model was edited, or the model comes '
            'from another run; train again'
        )
        raise CheckpointError(
            f'{run_file}: {key} is {_shown(ours)} there but {_shown(theirs)} in {meta_path}, {why}'
        )


def _shown(value: Any) -> str:
    return 'absent' if value is _ABSENT else short_json(value)


def _first_difference(ours: Any, theirs: Any, where: str) -> tuple[str, Any, Any] | None:
    """The first key path at which two JSON values differ, with both values; None if alike.

    Numbers compare by value (205 and 205.0 are one number; NaN is NaN), a boolean is no number.
    """
    if isinstance(ours, dict) and isinstance(theirs, dict):
        for key in [*ours, *(key for key in theirs if key not in ours)]:
            found = _first_difference(
                ours.get(key, _ABSENT), theirs.get(key, _ABSENT), f'{where}.{key}'
            )
            if found is not None:
                return found
        return None
    if isinstance(ours, list) and isinstance(theirs, list) and len(ours) == len(theirs):
        for k, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            found = _first_difference(a, b, f'{where}[{k}]')
            if found is not None:
                return found
        return None
    if ours is _ABSENT or theirs is _ABSENT or isinstance(ours, bool) != isinstance(theirs, bool):
        return where, ours, theirs
    both_nan = all(isinstance(x, float) and math.isnan(x) for x in (ours, theirs))
    return None if ours == theirs or both_nan else (where, ours, theirs)


def training_bag(run: dict[str, Any], run_dir: Path, index: int = 0) -> Path:
    """Where a run's ``index``-th training bag is now, wherever the command runs from.

    run.json holds the path as given to ``train`` (relative to where it ran) and, since it has
    it, the absolute path; a relative path is also tried beside the run folder, so a run and
    its bag moved together are still found.

    Raises:
        CheckpointError: the bag is at none of those places (each named).
    """
    entry = run['training_data']['bags'][index]
    given = Path(entry['path'])
    tried = [Path(entry['absolute_path'])] if entry.get('absolute_path') else []
    tried.append(given)
    if not given.is_absolute():
        tried.append(run_dir.parent / given)
    other = []
    for path in dict.fromkeys(tried):
        if path.exists():
            if 'sha256' not in entry or bag_sha256(path) == entry['sha256']:
                return path
            other.append(path)
    if other:
        raise CheckpointError(
            f'{run_dir}: its training bag {given} is not found: {other[0]} holds other data '
            '(another SHA-256); pass the bag or the twin config explicitly'
        )
    raise CheckpointError(
        f'{run_dir}: its training bag {given} is not found (tried '
        f'{", ".join(str(p) for p in dict.fromkeys(tried))}); move it back, or pass the bag '
        'or the twin config explicitly'
    )


def run_document(
    *,
    robot: RobotConfig,
    kinds: list[str],
    device: str,
    max_seconds_per_model: float | None,
    preprocessing: dict[str, Any],
    target_scaler: MinMaxScaler,
    training_data: dict[str, Any],
) -> dict[str, Any]:
    """run.json: how the run was made (robot, kinds, device, preprocessing, scaler, data)."""
    return {
        'format': RUN_FORMAT,
        # 'complete' once every model is scored and the report written (``train_run``).
        'status': 'incomplete',
        'created_unix_s': time.time(),
        'git_commit': _git_commit(),
        'robot': robot_fingerprint(robot),
        'robot_config': str(Path(robot.source).resolve()) if robot.source else None,
        'kinds': kinds,
        'device': device,
        'max_seconds_per_model': max_seconds_per_model,
        'preprocessing': preprocessing,
        'target_scaler': target_scaler.to_dict(),
        'training_data': training_data,
        'machine': machine_info(),
    }


def save_models(
    results: dict[str, ModelResult],
    table: dict[str, dict[str, Any]],
    *,
    preprocessing: dict[str, Any],
    target_scaler: MinMaxScaler,
    training_data: dict[str, Any],
) -> dict[str, str]:
    """Save each fitted model into its folder, with the run's settings and its own metrics.

    Returns each model's ``artifact_sha256`` (what its model.json holds), for run.json.
    """
    from id_learning.models.registry import save_model

    digests: dict[str, str] = {}
    for kind, result in results.items():
        save_model(
            result.model,
            result.folder,
            extra={
                'preprocessing': preprocessing,
                'target_scaler': target_scaler.to_dict(),
                'training_data': training_data,
                'metrics': {k: v for k, v in table[kind].items() if k != 'history'},
                'train_history': table[kind].get('history'),
            },
        )
        digests[kind] = str(read_metadata(result.folder / METADATA_FILE)[ARTIFACT_HASH])
    return digests


def metrics_document(
    kind: str,
    *,
    run: str | None = None,
    target: str,
    robot: RobotConfig,
    dataset: Dataset,
    evaluated_on: str,
    rows: list[tuple[int, int]],
    scale: np.ndarray,
    bags: list[dict[str, str]],
    table: dict[str, dict[str, Any]],
    findings: list[dict[str, Any]],
    machine: dict[str, Any],
    git_commit: str | None,
) -> dict[str, Any]:
    """metrics.json of a training run (``kind`` 'training') or an evaluation ('evaluation').

    Args:
        kind: 'training' or 'evaluation'.
        run: the evaluated run's folder (evaluations only; the key is left out otherwise).
        target: 'motor' or 'joint'.
        robot: the robot.
        dataset: the evaluated data (for the metric notes and the label-noise floor).
        evaluated_on: a sentence saying which data ``rows`` are.
        rows: the evaluated [start, stop) row ranges.
        scale: (n,) half ranges of the training labels [N*m].
        bags: per bag, its path and SHA-256.
        table: per model kind, its metrics entry.
        findings: the checked findings (JSON-ready).
        machine: ``machine_info()`` of the run.
        git_commit: the code's commit, where known.
    """
    return {
        'format': METRICS_FORMAT,
        'kind': kind,
        **({} if run is None else {'run': run}),
        'target': target,
        'joints': list(robot.joints),
        'evaluated_on': evaluated_on,
        **metric_notes(dataset),
        'n_samples': int(sum(b - a for a, b in rows)),
        'target_scale_nm': scale.tolist(),
        'bags': bags,
        'models': table,
        'findings': findings,
        'machine': machine,
        'git_commit': git_commit,
    }


def _bag_samples(bag: Path, robot: RobotConfig) -> Samples:
    """A bag's joint-state stamps and positions, in the robot's joint order."""
    from id_learning.bag import read_joint_states

    states = read_joint_states(bag, robot.topics.joint_states)
    if states.position is None or set(states.names) != set(robot.joints):
        return str(bag), np.zeros(0, dtype=np.int64), np.zeros((0, robot.n_joints))
    order = [states.names.index(name) for name in robot.joints]
    velocity = None if states.velocity is None else states.velocity[:, order]
    return str(bag), states.stamps_ns, states.position[:, order], velocity


def is_training_bag(bag: Path, run: dict[str, Any]) -> bool:
    """Whether ``bag`` is one of the run's training bags (by its content's hash)."""
    return bag_sha256(bag) in {e.get('sha256') for e in run['training_data']['bags']}


def refuse_training_samples(
    bags: list[Path], run: dict[str, Any], run_dir: Path, robot: RobotConfig
) -> None:
    """Refuse a new bag that holds samples of the run's training bags (cut from one of them).

    Scored as unseen, they would count training samples as test samples. Training bags that
    are not found cannot be compared; they are named in a warning.

    Raises:
        DatasetError: names the bag, the training bag and the shared span.
    """
    trained_on = run['training_data']['bags']
    new = [bag for bag in bags if not is_training_bag(bag, run)]
    if not new:
        return
    training: list[Samples] = []
    for index in range(len(trained_on)):
        try:
            training.append(_bag_samples(training_bag(run, run_dir, index), robot))
        except CheckpointError as err:
            _LOG.warning('cannot tell whether the bags hold training samples: %s', err)
    why = (
        'scored as a new recording it would count training samples as unseen; evaluate the '
        'training bag itself (its test part is scored) or a recording the run has not seen'
    )
    for bag in new:
        for known in training:
            refuse_shared_samples([_bag_samples(bag, robot), known], why)
