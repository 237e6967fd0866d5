"""Model artifacts: one folder per model with safetensors weights and JSON metadata. No pickle.

Loading checks that the file is what it claims (format, kind, tensor names and shapes), that it
belongs to the robot it is used with (name, joints and order, URDF hash, drives, units), that
every number a prediction uses is finite, and that nothing changed since it was written: the
weights match ``weights_sha256`` and the whole of model.json (that hash included) matches
``artifact_sha256``. Artifacts from before the whole-artifact hash load with a warning. Since a
hash written again after an edit proves nothing, what the metadata says must also make sense
(``metadata_checks``): each key once, scalers of the right length and width, one target, physical
parameters of the sign physics gives them.
"""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import math
import os
import re
import shutil
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NotRequired, TypedDict, cast

import numpy as np
from safetensors import SafetensorError
from safetensors.numpy import load_file, save_file

from id_learning import __version__
from id_learning.config_io import broken_link, not_a_file, read_capped
from id_learning.dataset.inputs import InputDefinition
from id_learning.errors import CheckpointError
from id_learning.models.metadata_checks import DuplicateKeyError, check_metadata, loads_unique
from id_learning.outputs import replace_folder
from id_learning.robot.config import RobotConfig

__all__ = [
    'ARTIFACT_FORMAT',
    'ARTIFACT_HASH',
    'METADATA_FILE',
    'UNITS',
    'WEIGHTS_FILE',
    'ArtifactExtra',
    'ModelDocument',
    'RobotFingerprint',
    'artifact_inputs',
    'artifact_target',
    'document_digest',
    'read_artifact',
    'read_metadata',
    'robot_fingerprint',
    'write_artifact',
]

_LOG = logging.getLogger(__name__)

ARTIFACT_FORMAT = 'id_learning.model/1'
METADATA_FILE = 'model.json'
WEIGHTS_FILE = 'weights.safetensors'
UNITS = {'q': 'rad', 'v': 'rad/s', 'a': 'rad/s^2', 'tau': 'N*m joint side', 'current': 'A'}


class DriveFingerprint(TypedDict):
    """The drives a model's torques were converted with (motor side, per joint)."""

    gear_ratio: list[float]
    torque_constant_nm_per_a: list[float]
    rotor_inertia_motor_side_kgm2: list[float]


class RobotFingerprint(TypedDict):
    """What ties a model to a robot."""

    name: str
    joints: list[str]
    urdf_sha256: str
    drives: DriveFingerprint
    #: The IPO period its recordings were made at [s]; absent in artifacts from before it.
    ipo_period_s: NotRequired[float]


class ArtifactExtra(TypedDict, total=False):
    """What a run stores beside a model: how its data were made, and how the model scored."""

    #: ``PreprocessConfig`` as a dict, with the input definitions (``preprocessing.target``).
    preprocessing: dict[str, Any]
    #: The run's torque scaler (``MinMaxScaler.to_dict``).
    target_scaler: dict[str, Any]
    #: The bags (path, SHA-256) and splits the model was fitted on.
    training_data: dict[str, Any]
    #: Test metrics per joint, as in the run's metrics table.
    metrics: dict[str, Any]
    #: Loss per epoch of the network kinds; None for closed-form fits.
    train_history: Any
    #: The diagnosis that built an ``rnea_effects`` model: the sources it read.
    diagnosis: dict[str, Any]


class ModelDocument(ArtifactExtra):
    """model.json: the artifact's header, the model's settings and fitted values, the run's.

    The file also holds ``ARTIFACT_HASH``, the SHA-256 of the rest (absent in artifacts from
    before it).
    """

    format: str
    kind: str
    robot: RobotFingerprint
    units: dict[str, str]
    #: Tensor name -> shape, as in weights.safetensors.
    tensors: dict[str, list[int]]
    weights_sha256: str
    package_version: str
    git_commit: str | None
    #: The model config (``ModelConfig.to_dict``).
    hyperparameters: dict[str, Any]
    #: ``InverseDynamicsModel.fitted_metadata``: scalers, identified parameters, fit summaries.
    fitted: dict[str, Any]


def robot_fingerprint(robot: RobotConfig) -> RobotFingerprint:
    """What ties a model to a robot: name, joints in order, URDF hash, drives."""
    drives = _drive_values(robot)
    return {
        'name': robot.name,
        'joints': list(robot.joints),
        'urdf_sha256': robot.urdf_sha256(),
        'drives': {
            'gear_ratio': drives['gear_ratio'],
            'torque_constant_nm_per_a': drives['torque_constant_nm_per_a'],
            'rotor_inertia_motor_side_kgm2': drives['rotor_inertia_motor_side_kgm2'],
        },
        'ipo_period_s': robot.ipo_period_s,
    }


def _drive_values(robot: RobotConfig) -> dict[str, list[float]]:
    """The robot's drives by their fingerprint names."""
    return {
        'gear_ratio': robot.drives.gear_ratio.tolist(),
        'torque_constant_nm_per_a': robot.drives.torque_constant.tolist(),
        'rotor_inertia_motor_side_kgm2': robot.drives.rotor_inertia.tolist(),
    }


def _git_commit() -> str | None:
    try:
        result = subprocess.run(
            ['git', 'rev-parse', 'HEAD'],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return result.stdout.strip() or None


def write_artifact(
    folder: Path,
    kind: str,
    robot: RobotConfig,
    tensors: dict[str, np.ndarray],
    *,
    settings: dict[str, Any],
    fitted: dict[str, Any],
    extra: ArtifactExtra | None = None,
) -> Path:
    """Write ``weights.safetensors`` and ``model.json`` into ``folder``, whole or not at all.

    Both files are written into a hidden sibling that is then renamed to ``folder`` (an artifact
    already there is replaced the same way): a reader never meets half an artifact, and a write
    that fails (disk full) leaves none.

    Raises:
        OSError: a write failed (the hidden sibling is removed).
        CheckpointError: the metadata would be refused when read (``metadata_checks``: a
            degenerate scaler, a physical parameter of the wrong sign); nothing is written.
    """
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.with_name(f'.{folder.name}.tmp-{os.getpid()}')
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        _write_files(tmp, kind, robot, tensors, (settings, fitted, extra or {}))
        replace_folder(tmp, folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _write_files(
    folder: Path,
    kind: str,
    robot: RobotConfig,
    tensors: dict[str, np.ndarray],
    contents: tuple[dict[str, Any], dict[str, Any], ArtifactExtra],
) -> None:
    """The two files of an artifact, into ``folder``: contents are (settings, fitted, extra)."""
    contiguous = {name: np.ascontiguousarray(value) for name, value in tensors.items()}
    try:
        save_file(contiguous, str(folder / WEIGHTS_FILE))
    except SafetensorError as err:  # a failed write, as '... I/O error: ... (os error 28)'
        found = re.search(r'os error (\d+)', str(err))
        code = int(found.group(1)) if found else errno.EIO
        raise OSError(code, os.strerror(code), str(folder / WEIGHTS_FILE)) from err
    # safetensors creates its file 0600: as readable as the folder (made under the umask, as
    # model.json is), so that a predictor node running as another user can load the artifact.
    os.chmod(folder / WEIGHTS_FILE, folder.stat().st_mode & 0o666)
    settings, fitted, extra = contents
    document = ModelDocument(
        **extra,
        format=ARTIFACT_FORMAT,
        kind=kind,
        robot=robot_fingerprint(robot),
        units=UNITS,
        tensors={name: list(value.shape) for name, value in contiguous.items()},
        weights_sha256=hashlib.sha256((folder / WEIGHTS_FILE).read_bytes()).hexdigest(),
        package_version=__version__,
        git_commit=_git_commit(),
        hyperparameters=settings,
        fitted=fitted,
    )
    # Nothing is written that a load would refuse.
    paths = (folder / METADATA_FILE, folder / WEIGHTS_FILE)
    check_metadata(document, contiguous, *paths, tuple(robot.joints))
    written = {**document, ARTIFACT_HASH: document_digest(document)}
    (folder / METADATA_FILE).write_text(json.dumps(written, indent=1) + '\n', encoding='utf-8')


#: model.json's key for the hash of its own contents (which include the weights' hash).
ARTIFACT_HASH = 'artifact_sha256'


def document_digest(document: Mapping[str, Any]) -> str:
    """SHA-256 of model.json's contents without its own hash, in a canonical JSON form.

    A tool that edits model.json on purpose (a migration) stores this again as ``ARTIFACT_HASH``.
    """
    body = {key: value for key, value in document.items() if key != ARTIFACT_HASH}
    canonical = json.dumps(body, sort_keys=True, separators=(',', ':'))
    return hashlib.sha256(canonical.encode('utf-8')).hexdigest()


def _check_unchanged(metadata: Mapping[str, Any], meta_path: Path) -> None:
    """Refuse a model.json changed after it was written; warn for one from before the hash."""
    saved = metadata.get(ARTIFACT_HASH)
    if saved is None:
        _LOG.warning(
            '%s: written before artifacts hashed their metadata (no %s); only the weights are '
            'verified',
            meta_path,
            ARTIFACT_HASH,
        )
    elif saved != document_digest(metadata):
        raise CheckpointError(
            f'{meta_path}: its contents do not match its {ARTIFACT_HASH}: a field was changed '
            'after the model was written; retrain or restore the file'
        )


def _check_robot(saved: Any, robot: RobotConfig, folder: Path) -> None:
    if not isinstance(saved, dict):
        raise CheckpointError(f'{folder}: model.json has no robot object, got {saved!r}')
    current = robot_fingerprint(robot)
    if saved.get('joints') != current['joints']:
        raise CheckpointError(
            f'{folder}: model joints {saved.get("joints")} do not match robot {robot.name} '
            f'joints {current["joints"]} (names and order must agree)'
        )
    for key in ('name', 'urdf_sha256'):
        if saved.get(key) != current[key]:
            urdf = (
                f' (the URDF given: {robot.urdf_path}; a URDF whose bytes differ, even only in '
                'comments or line ends, is another robot here: give the one the model was '
                'trained with)'
                if key == 'urdf_sha256'
                else ''
            )
            raise CheckpointError(
                f'{folder}: model was trained for robot {key} {saved.get(key)!r}, '
                f'not {current[key]!r}{urdf}'
            )
    for key, values in _drive_values(robot).items():
        if not np.allclose(saved.get('drives', {}).get(key, []), values, rtol=1e-12, atol=0):
            raise CheckpointError(f'{folder}: drive parameter {key} differs from the robot config')


#: The largest model.json read [bytes]; real ones hold a few hundred kB (histories included).
MAX_METADATA_BYTES = 64 * 2**20
#: The deepest nesting of objects and lists in a model.json read; real ones nest 8 deep.
MAX_METADATA_DEPTH = 64


def _nesting_depth(value: Any) -> int:
    """How deep objects and lists nest in ``value`` (iteratively: no recursion limit)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (dict, list)):
            deepest = max(deepest, depth)
            children = item.values() if isinstance(item, dict) else item
            stack.extend((child, depth + 1) for child in children)
    return deepest


def read_metadata(meta_path: Path) -> dict[str, Any]:
    """Read a model.json into a mapping, bounded in size and nesting.

    Raises:
        CheckpointError: the file is unreadable, no regular file (a FIFO, a device: named,
            never waited on), larger than ``MAX_METADATA_BYTES``, not valid
            JSON, holds a key twice in one object, nested deeper than ``MAX_METADATA_DEPTH``, or
            not a JSON object; names it (and the key).
    """
    meta_path = Path(meta_path)
    link = broken_link(meta_path)
    if link is not None:
        raise CheckpointError(f'{meta_path}: {link}; restore it, or copy the artifact whole')
    data = read_capped(
        meta_path, 'model metadata', MAX_METADATA_BYTES, regular=True, error=CheckpointError
    )
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise CheckpointError(f'{meta_path}: cannot read model metadata: {err}') from err
    try:
        metadata = loads_unique(text)
    except DuplicateKeyError as err:
        raise CheckpointError(f'{meta_path}: {err}; the file was edited or is corrupt') from err
    except json.JSONDecodeError as err:
        raise CheckpointError(f'{meta_path}: not valid JSON: {err}') from err
    except RecursionError:
        metadata = None  # nested beyond the parser's stack: refused below by its depth
    depth = MAX_METADATA_DEPTH + 1 if metadata is None else _nesting_depth(metadata)
    if depth > MAX_METADATA_DEPTH:
        raise CheckpointError(
            f'{meta_path}: nested deeper than a model.json ({MAX_METADATA_DEPTH} levels at '
            'most); the file is corrupt or not a model artifact'
        )
    if not isinstance(metadata, dict):
        raise CheckpointError(f'{meta_path}: format is not {ARTIFACT_FORMAT!r} (not an object)')
    return metadata


def read_artifact(
    folder: Path, robot: RobotConfig, kind: str | None = None
) -> tuple[ModelDocument, dict[str, np.ndarray]]:
    """Read and verify an artifact; returns (model.json, tensors).

    Raises:
        CheckpointError: a path that is no folder (a file, a FIFO, a device, a link to
            nothing: named, never opened), missing files, wrong format or kind, a key given
            twice, a tensor list or hash that does not match the metadata, wrong units, a
            robot/joint/drive mismatch, a non-finite number, a scaler of the wrong length or of
            zero width, targets that disagree, a physical parameter of the wrong sign
            (``metadata_checks``), or a model.json changed after it was written. A newer
            package version is warned of.
    """
    folder = Path(folder)
    _refuse_no_folder(folder)
    meta_path, weights_path = folder / METADATA_FILE, folder / WEIGHTS_FILE
    for path in (meta_path, weights_path):
        what = not_a_file(path)
        link = broken_link(path)
        if link is not None:
            raise CheckpointError(f'{path}: {link}; restore it, or copy the artifact whole')
        if what == 'no such file':
            raise CheckpointError(
                f'{folder}: not a model artifact (needs {METADATA_FILE} and {WEIGHTS_FILE})'
            )
        if what is not None:
            raise CheckpointError(f'{path}: {what}, not a regular file as an artifact holds')
    metadata = read_metadata(meta_path)
    if metadata.get('format') != ARTIFACT_FORMAT:
        raise CheckpointError(f'{meta_path}: format is not {ARTIFACT_FORMAT!r}')
    if kind is not None and metadata.get('kind') != kind:
        raise CheckpointError(f'{folder}: holds a {metadata.get("kind")!r} model, not {kind!r}')
    if metadata.get('units') != UNITS:
        raise CheckpointError(f'{meta_path}: units {metadata.get("units")} differ from {UNITS}')
    digest = hashlib.sha256(weights_path.read_bytes()).hexdigest()
    try:
        tensors = load_file(str(weights_path))
    except (SafetensorError, OSError, ValueError) as err:
        raise CheckpointError(f'{weights_path}: not a valid safetensors file: {err}') from err
    # Non-finite values first: a NaN written into the weights is named as such, whether or not
    # the hash was updated with it.
    for name, value in tensors.items():
        bad = np.flatnonzero(~np.isfinite(np.asarray(value, dtype=float)))
        if bad.size:
            raise CheckpointError(
                f'{weights_path}: tensor {name} holds {bad.size} non-finite value(s) (first at '
                f'flat index {int(bad[0])}); a model never predicts from them'
            )
    if digest != metadata.get('weights_sha256'):
        raise CheckpointError(f'{weights_path}: contents do not match the hash in {METADATA_FILE}')
    shapes = {name: list(value.shape) for name, value in tensors.items()}
    if shapes != metadata.get('tensors'):
        raise CheckpointError(f'{weights_path}: tensors {shapes} differ from the metadata')
    for key in ('fitted', 'target_scaler'):
        _check_finite(metadata.get(key), key, meta_path)
    _check_robot(metadata.get('robot', {}), robot, folder)
    # Scalers, targets, the signs of physical parameters, the package version.
    check_metadata(metadata, tensors, meta_path, weights_path, tuple(robot.joints))
    # Last, so that a specific fault (another robot, a NaN field) is named as such.
    _check_unchanged(metadata, meta_path)
    for key in ('hyperparameters', 'fitted'):
        if not isinstance(metadata.setdefault(key, {}), dict):
            raise CheckpointError(
                f'{meta_path}: model.json has no {key} object, got {metadata[key]!r}'
            )
    # Its header is verified above (format, kind, units, tensors, hashes, robot, the fitted
    # values' numbers); the model's own loader checks its settings and fitted values.
    return cast(ModelDocument, metadata), tensors


def _refuse_no_folder(folder: Path) -> None:
    """Refuse an artifact path that is no folder, naming what it is, without opening it.

    A FIFO given as the artifact is never opened (that would wait for a writer), a regular file
    (a model.json given instead of its folder) is named as a file. A path that does not exist
    is named so, with the working directory a relative path was taken in (a launch file or
    parameter file run from elsewhere).

    Raises:
        CheckpointError: the path does not exist, is a file, a FIFO, a device or socket, or a
            link to nothing.
    """
    expected = f'expected a folder with {METADATA_FILE} and {WEIGHTS_FILE}'
    link = broken_link(folder)
    if link is not None:
        raise CheckpointError(f'{folder}: {link}; a model artifact is a folder ({expected})')
    kind = not_a_file(folder)
    if kind is None:
        raise CheckpointError(f'{folder}: a regular file, not a model folder ({expected})')
    if kind not in ('a folder', 'no such file') and not kind.startswith('cannot be read'):
        raise CheckpointError(f'{folder}: {kind}, not a model folder ({expected})')
    if kind == 'no such file':
        relative = (
            ''
            if folder.is_absolute()
            else f' (a path relative to the working directory {Path.cwd()})'
        )
        raise CheckpointError(
            f'{folder}: no such folder, so not a model artifact (needs {METADATA_FILE} and '
            f'{WEIGHTS_FILE}){relative}'
        )


#: Summaries in the fitted metadata that describe the fit and never enter a prediction (a loss
#: may be inf before the first epoch, a condition number inf for a rank-deficient recording).
SUMMARY_KEYS = ('training', 'history', 'report', 'diagnosis')


def _check_finite(value: Any, where: str, path: Path) -> None:
    """Refuse NaN or inf anywhere in the numbers a model predicts from, naming the field.

    Raises:
        CheckpointError: names the file and the field (e.g. fitted.input_scaler.low[3]).
    """
    if isinstance(value, float) and not math.isfinite(value):
        raise CheckpointError(f'{path}: {where} is {value}; a model file holds finite numbers')
    if isinstance(value, dict):
        for key, item in value.items():
            if key not in SUMMARY_KEYS:
                _check_finite(item, f'{where}.{key}', path)
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _check_finite(item, f'{where}[{index}]', path)


def artifact_target(metadata: Mapping[str, Any]) -> str:
    """What an artifact's model predicts: 'motor' (tau_u) or 'joint' torques.

    From the run's preprocessing (``train`` writes it), else from what the model itself keeps;
    'motor' where neither says.
    """
    fitted = metadata.get('fitted') or {}
    for holder in (metadata.get('preprocessing'), fitted, fitted.get('physics')):
        if isinstance(holder, dict) and holder.get('target') in ('motor', 'joint'):
            return str(holder['target'])
    return 'motor'


def artifact_inputs(
    metadata: Mapping[str, Any],
) -> tuple[InputDefinition | None, InputDefinition | None]:
    """The input definitions an artifact stores: what it is served on, what it was fitted on.

    Artifacts written before input definitions existed store neither (None, None); they were
    fitted on the study's low-passed inputs.

    Raises:
        CheckpointError: a stored definition is malformed.
    """
    preprocessing = metadata.get('preprocessing') or {}
    inputs, fitting = preprocessing.get('inputs'), preprocessing.get('fitting_inputs')
    return (
        None if inputs is None else InputDefinition.from_dict(inputs),
        None if fitting is None else InputDefinition.from_dict(fitting),
    )
