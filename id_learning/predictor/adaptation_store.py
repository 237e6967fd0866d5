"""The adaptation's learnt values across predictor sessions: ``<artifact>.adaptation.json``.

A session starts from what the file holds (when it was learnt on the same model, for the same
joints and mode) and writes back only when it learnt something: a session that accepted no update
(NaN currents, a reference always stale) leaves the file as it was, so that it never erases what
an earlier one learnt. Writing is atomic (a temporary file, flushed to disk, then renamed over the
old one). A file that cannot be continued from is never overwritten: it is kept as
``<file>.previous`` (or ``.previous.N``) before a new one is written. It cannot be continued from
when it is unreadable, for other joints, mode or base parameters, or holds a value the adaptation
never reaches online: not finite, beyond the limits it keeps its estimate and error scale within
(``ESTIMATE_PRIOR_STDS`` prior standard deviations, the torque limit), an applied correction
beyond its bound, or an error scale of 0 (which would gate every sample); the reason names the
key, the joint and the value.

The file belongs to one model: it records the ``artifact_sha256`` of the model.json it was learnt
on. One learnt on another model (a run retrained in place under the predictor), or written
before files recorded it, is not continued from: it is kept as ``<file>.model-<its sha's
start>``. At the end of a session the state goes where the model it was learnt on is:

- beside the artifact, when its model.json still holds the sha the session started with;
- beside the same model in the completed run, when the artifact lay in ``<run>.partial`` and
  train has since renamed the folder to ``<run>``;
- otherwise (the model replaced under the predictor, its folder gone, or the file not writable)
  never over another model's state: to ``<artifact>.adaptation.json.model-<sha's start>`` in the
  nearest folder that still exists, else in ``$XDG_STATE_HOME/id_learning`` (``~/.local/state``),
  with a warning naming the file. Each attempt that failed is named when none succeeds.

Two sessions on one artifact (two predictors) never overwrite each other's learning: a session
records the file's content (sha256) when it loads, and at save, when the file changed meanwhile
(another session saved there, or created it), leaves it as it is and writes its own state beside
it, to ``<file>.session-<pid>``, with a warning naming both and that the two sessions' learning is
not merged. The check and the write hold an flock on the folder, so two saves do not interleave.
Nothing blocks the feed-forward: both sessions adapt and serve as before.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import re
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from id_learning.config_io import read_capped
from id_learning.errors import CheckpointError, ConfigError
from id_learning.models.artifact import ARTIFACT_HASH, METADATA_FILE, read_metadata
from id_learning.outputs import PARTIAL_SUFFIX, partial_path

__all__ = [
    'ADAPTATION_JSON',
    'COLUMNS',
    'ESTIMATE_PRIOR_STDS',
    'AdaptationLoop',
    'StoredBase',
    'adaptation_path',
    'load_base',
    'model_identity',
    'save_state',
    'unlearnt_line',
    'unloaded_base',
]


#: The friction terms per joint, in the order of the stored arrays' columns.
COLUMNS = ('coulomb_level_nm', 'viscous_nms_per_rad', 'offset_nm')
#: The adapters keep each estimated parameter within this many prior standard deviations.
ESTIMATE_PRIOR_STDS = 100.0
#: The largest adaptation state read (a few kB are written; a larger file is another one).
MAX_STATE_BYTES = 2**20
#: Rounding allowed on a stored value at its limit.
_SLACK = 1e-9


class _Estimator(Protocol):
    """An adapter whose estimate a stored state continues."""

    @property
    def estimate_limit(self) -> np.ndarray:
        """How far each estimated parameter may go (the estimate's shape)."""

    @property
    def error_scale_limit(self) -> np.ndarray:
        """The largest error scale per joint (n,)."""

    def restore(self, estimate: np.ndarray, error_scale: np.ndarray) -> None:
        """Continue from a stored estimate and error scale (n,)."""


class _FrictionEstimator(_Estimator, Protocol):
    """The friction adapter: what it applies is its estimate within ``bounds``."""

    @property
    def bounds(self) -> np.ndarray:
        """(n, 3) the bound of each applied friction term."""


class _BodyEstimator(_Estimator, Protocol):
    """The inertial adapter: its estimate also holds the base parameters' changes."""

    @property
    def names(self) -> Sequence[str]:
        """The base parameters' names."""


class AdaptationLoop(Protocol):
    """What the store needs of ``adaptation.AdaptationLoop`` (kept apart: no import cycle)."""

    @property
    def adapter(self) -> _FrictionEstimator:
        """The friction adapter."""

    @property
    def inertia(self) -> _BodyEstimator | None:
        """The inertial adapter (mode rls_inertia), else None."""

    @property
    def session_updates(self) -> int:
        """Updates accepted in this session."""

    def state(self, joints: tuple[str, ...]) -> dict[str, Any]:
        """The JSON-ready state to store."""

    base: StoredBase | None


#: Where adapted parameters are saved beside (never over) an artifact.
ADAPTATION_JSON = 'adaptation.json'


@dataclass(frozen=True)
class StoredBase:
    """What a session found in the file at start.

    Attributes:
        path: the file.
        updates_before: accepted updates of the earlier sessions (0 when not continued from).
        problem: why the file could not be continued from, or None (continued from).
        found: the file was there at start.
        model_sha256: the ``artifact_sha256`` of the model the session runs (None: its
            model.json records none), what the state is stored for.
        artifact: the artifact folder (None: the one ``path`` is named for).
        aside_tag: the suffix of the name a file not continued from is kept under.
        read: ``load_base`` looked at the file: ``content`` is what it held.
        content: the sha256 of the file when read or last written by this session (None: none).
        side: where this session's state went beside a file another session changed.
        elsewhere: with no file at ``path``, a state of this model an earlier session saved in
            a fallback place (named at start, so that it is not taken for lost).
    """

    path: Path
    updates_before: int = 0
    problem: str | None = None
    found: bool = True
    model_sha256: str | None = None
    artifact: Path | None = None
    aside_tag: str = 'previous'
    read: bool = False
    content: str | None = None
    side: Path | None = None
    elsewhere: Path | None = None

    @property
    def folder(self) -> Path:
        """The artifact folder the state is for."""
        if self.artifact is not None:
            return self.artifact
        return self.path.with_name(self.path.name.removesuffix(f'.{ADAPTATION_JSON}'))

    def line(self) -> tuple[bool, str] | None:
        """(is a warning, what the session starts from) for the log; None: there was no file."""
        if self.problem is not None:
            return True, (
                f'adaptation starts from zero: {self.path} cannot be continued from '
                f'({self.problem}); it is kept as {self.path.name}.{self.aside_tag} if this '
                'session learns'
            )
        if not self.found and self.elsewhere is not None:
            return True, (
                f"adaptation starts from zero: there is no {self.path}, but this model's state "
                f'of an earlier session lies at {self.elsewhere} (saved there when its own place '
                f'could not be written): move it to {self.path} to continue from it'
            )
        if not self.found:
            return None
        return False, (
            f'adaptation continues from {self.path} ({self.updates_before} updates in earlier '
            'sessions)'
        )

    def untouched(self) -> str:
        """What became of the file when a session learnt nothing (nothing is written)."""
        if self.path.exists():
            return f'{self.path} is left as it was'
        return f'none written, and there is none at {self.path}'


def unlearnt_line(
    gated: int, frozen: tuple[int, str], unpaired: int, base: StoredBase
) -> tuple[bool, str]:
    """(is a warning, the line) of a session that learnt nothing; gated samples warn (why)."""
    gate = f'{gated} joint samples gated, {_GATED_ALL}; ' if gated else ''
    return gated > 0, (
        f'adaptation accepted no update this session ({gate}{frozen[0]} frozen samples, the '
        f'latest: {frozen[1]}; {unpaired} currents unpaired); {base.untouched()}'
    )


def adaptation_path(artifact: Path | str) -> Path:
    """``<artifact>.adaptation.json`` beside the artifact folder (never in it: it is hashed)."""
    artifact = Path(artifact).resolve()
    return artifact.parent / f'{artifact.name}.{ADAPTATION_JSON}'


def _mode(loop: AdaptationLoop) -> str:
    return 'rls' if loop.inertia is None else 'rls_inertia'


def _array(state: dict[str, Any], key: str, shape: tuple[int, ...]) -> np.ndarray:
    """A finite array of the given shape from the stored state (ValueError naming the key)."""
    value = np.asarray(state.get(key), dtype=float)
    if value.shape != shape or not np.isfinite(value).all():
        raise ValueError(f'{key!r} is not {shape} finite numbers')
    return value


def _within(key: str, values: np.ndarray, limit: np.ndarray, names: list[str], why: str) -> None:
    """ValueError naming the first value beyond ``limit`` (same shape): its key, name, value."""
    over = np.flatnonzero(np.abs(values) > np.asarray(limit) * (1 + _SLACK))
    if over.size:
        k = int(over[0])
        raise ValueError(
            f'{key!r} of {names[k]} is {values.flat[k]:.6g}, beyond the '
            f'{np.asarray(limit).flat[k]:.6g} {why}'
        )


def _check_scale(scale: np.ndarray, limit: np.ndarray, joints: tuple[str, ...]) -> None:
    """ValueError naming a joint whose stored error scale the adaptation never holds."""
    for j, name in enumerate(joints):
        if not scale[j] > 0:
            raise ValueError(
                f"'error_scale_nm' of {name} is {scale[j]:.6g}, not above 0 (it scales the "
                'outlier gate: every sample would be gated)'
            )
    _within('error_scale_nm', scale, limit, list(joints), 'N*m torque limit it is kept within')


def _restore(loop: AdaptationLoop, state: dict[str, Any], joints: tuple[str, ...]) -> None:
    """Set the loop's estimates from a stored state (ValueError: it does not fit the loop).

    Every value is checked against what the adaptation keeps online before anything is set:
    a state beyond it is no earlier session's (a corrupt or edited file).
    """
    if state.get('joints') != list(joints):
        raise ValueError(f"joints {state.get('joints')} are not the model's {list(joints)}")
    if state.get('mode', 'rls') != _mode(loop):
        raise ValueError(f'mode {state.get("mode", "rls")!r}, this session runs {_mode(loop)!r}')
    n = len(joints)
    terms = [f'{joint} {column}' for joint in joints for column in COLUMNS]
    scale = _array(state, 'error_scale_nm', (n,))
    estimated = 'the adaptation keeps its estimate within'
    if loop.inertia is None:
        adapter = loop.adapter
        _check_scale(scale, adapter.error_scale_limit, joints)
        theta = _array(state, 'theta', (n, 3))
        _within('theta', theta, adapter.bounds, terms, 'the applied correction is bounded to')
        estimate = _array(state, 'estimate', (n, 3)) if 'estimate' in state else theta
        _within('estimate', estimate, adapter.estimate_limit, terms, estimated)
        adapter.restore(estimate, scale)
        return
    body = loop.inertia
    if state.get('base_parameters') != list(body.names):
        raise ValueError("its base parameters are not the robot model's")
    _check_scale(scale, body.error_scale_limit, joints)
    friction = _array(state, 'theta', (n, 3))
    change = _array(state, 'change', (len(body.names),))
    limit = np.asarray(body.estimate_limit)
    _within('theta', friction, limit[: 3 * n].reshape(n, 3), terms, estimated)
    names = [f'base parameter {name}' for name in body.names]
    _within('change', change, limit[3 * n :], names, estimated)
    body.restore(np.concatenate([friction.reshape(-1), change]), scale)


def model_identity(artifact: Path | str) -> str | None:
    """The ``artifact_sha256`` the artifact's model.json holds now.

    None: it records none (an artifact from before the hash) or there is no model.json; the
    state of such a model cannot be told from another's of the same kind.

    Raises:
        CheckpointError: model.json is there but unreadable.
    """
    meta = Path(artifact) / METADATA_FILE
    if not os.path.lexists(meta):
        return None
    digest = read_metadata(meta).get(ARTIFACT_HASH)
    return digest if isinstance(digest, str) else None


def _short(digest: object) -> str:
    """The start of a sha for a message ('none recorded' for None)."""
    return f'{digest[:12]}...' if isinstance(digest, str) else 'none recorded'


def _model_tag(digest: object) -> str:
    """``model-<its start>`` for the names of files of the model with ``digest``."""
    hex_start = digest[:12] if isinstance(digest, str) else ''
    return f'model-{hex_start}' if re.fullmatch('[0-9a-f]{12}', hex_start) else 'model-unknown'


#: Why every sample of a session that learnt nothing was gated, on a sound stream.
_GATED_ALL = "the measured tau_u lay far from the model's: currents [A] on measured_topic?"
#: A key the stored state lacks, or a model.json that cannot be read.
_ABSENT = object()


class _OtherModelError(ValueError):
    """The stored state was learnt on another model than the session's (or says not on which)."""

    def __init__(self, stored: object, model: str | None) -> None:
        if stored is _ABSENT:
            why = (
                f'it records no model ({ARTIFACT_HASH}): written before adaptation states '
                "recorded the model they were learnt on, it may be another model's; this "
                f"model's is {_short(model)} (to continue from it all the same, add "
                f'"{ARTIFACT_HASH}": "{model}" to it)'
            )
        else:
            why = (
                f'learnt on another model: its {ARTIFACT_HASH} is {_short(stored)}, this '
                f"model's is {_short(model)}"
            )
        super().__init__(why)
        self.tag = _model_tag(None if stored is _ABSENT else stored)


def _base(artifact: Path | str, model_sha256: str | None = None) -> StoredBase:
    """A fresh base for ``artifact`` (resolved), of the given model (None: as model.json says)."""
    artifact = Path(artifact).resolve()
    if model_sha256 is None:
        try:
            model_sha256 = model_identity(artifact)
        except CheckpointError:  # the predictor loaded it: only a folder changed under it
            model_sha256 = None
    return StoredBase(adaptation_path(artifact), model_sha256=model_sha256, artifact=artifact)


def unloaded_base(artifact: Path | str) -> StoredBase:
    """The base of a session that did not ``load``: its file is not continued from."""
    return replace(_base(artifact), problem='not loaded at start')


def load_base(
    loop: AdaptationLoop,
    artifact: Path | str,
    joints: tuple[str, ...],
    model_sha256: str | None = None,
) -> StoredBase:
    """Continue the loop from the stored file when it fits; what was found (no file: zero).

    ``model_sha256``: the ``artifact_sha256`` of the model the session runs, as it was loaded
    (None: read from the artifact's model.json now).
    """
    base = _base(artifact, model_sha256)
    path = base.path
    base = replace(base, read=True, content=_digest(path))
    if not path.exists():
        elsewhere = next((p for p in _elsewhere(base) if p.is_file()), None)
        return replace(base, found=False, elsewhere=elsewhere)
    try:
        state = json.loads(
            read_capped(path, 'adaptation state', MAX_STATE_BYTES, regular=True).decode('utf-8')
        )
        if not isinstance(state, dict):
            raise ValueError('not a JSON object')
        stored = state.get(ARTIFACT_HASH, _ABSENT)
        if stored != base.model_sha256:
            raise _OtherModelError(stored, base.model_sha256)
        _restore(loop, state, joints)
        before = int(state.get('updates_total', state.get('updates')) or 0)
    except _OtherModelError as err:
        return replace(base, problem=str(err), aside_tag=err.tag)
    except (ConfigError, ValueError, TypeError) as err:  # JSONDecodeError is a ValueError
        return replace(base, problem=str(err) or type(err).__name__)
    return replace(base, updates_before=before)


def _free(path: Path) -> Path:
    """``path``, or ``path.N`` with the first N free: a name that overwrites nothing."""
    candidate, k = path, 1
    while os.path.lexists(candidate):
        candidate = path.with_name(f'{path.name}.{k}')
        k += 1
    return candidate


def _write(path: Path, state: dict[str, Any]) -> None:
    """Write ``state`` to a temporary file, flush it to disk, rename it to ``path``."""
    tmp = path.with_name(f'.{path.name}.tmp')
    try:
        with tmp.open('w', encoding='utf-8') as stream:
            stream.write(json.dumps(state, indent=2))
            stream.flush()
            os.fsync(stream.fileno())
        tmp.replace(path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise


def _digest(path: Path) -> str | None:
    """The sha256 of the file at ``path`` (None: there is none; unreadable: says so)."""
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_STATE_BYTES:  # never waited on
            return f'mode {info.st_mode:o}, {info.st_size} bytes, at {info.st_mtime_ns} ns'
        with path.open('rb') as stream:
            return hashlib.file_digest(stream, 'sha256').hexdigest()
    except FileNotFoundError:
        return None
    except OSError as err:
        return f'unreadable ({err.strerror or err})'


@contextlib.contextmanager
def _folder_locked(folder: Path) -> Iterator[None]:
    """Hold an flock on ``folder`` while a save checks and writes (none where it cannot)."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        yield
        return
    try:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _changed(base: StoredBase, path: Path) -> bool:
    """Whether another session wrote ``path`` since this one read (or last wrote) it."""
    return base.read and _digest(path) != base.content


def _beside(path: Path, base: StoredBase, state: dict[str, Any]) -> tuple[Path, str]:
    """Write the state beside ``path`` (another session's now): (where, what became of both)."""
    side = base.side or _free(path.with_name(f'{path.name}.session-{os.getpid()}'))
    _write(side, state)
    return side, (
        f'; {path} was changed by another session since this one read it (two sessions adapted '
        f"on one artifact): it is left as it is, and this session's state is written to {side} "
        f"instead: the two sessions' learning is not merged (to continue from this one, rename "
        f'it to {path.name})'
    )


def _saved(loop: AdaptationLoop, base: StoredBase, path: Path, side: bool) -> None:
    """Record where this session's state went: its next save checks against what it wrote."""
    if side:
        loop.base = replace(base, side=path)
    else:
        loop.base = replace(base, problem=None, found=True, read=True, content=_digest(path))


@dataclass(frozen=True)
class _Place:
    """Where a session's state goes: the model's own file, or ``None`` (elsewhere), and why."""

    own: Path | None
    why: str = ''
    warn: bool = False


def _final_artifact(artifact: Path) -> Path | None:
    """Where ``artifact`` is once the run folder it lies in (``<run>.partial``) is complete."""
    for folder in artifact.parents:
        name = folder.name.removesuffix(PARTIAL_SUFFIX)
        if name and name != folder.name and partial_path(folder.with_name(name)) == folder:
            return folder.with_name(name) / artifact.relative_to(folder)
    return None


def _held(artifact: Path) -> str | object | None:
    """``model_identity``, or ``_ABSENT`` when model.json is unreadable (no model known)."""
    try:
        return model_identity(artifact)
    except CheckpointError:
        return _ABSENT


def _placement(base: StoredBase) -> _Place:
    """Where the state of the model ``base`` was loaded for goes now (``save_state``)."""
    artifact, start = base.folder, base.model_sha256
    if artifact.is_dir():
        held = _held(artifact)
        if held == start:
            return _Place(base.path)
        now = 'unreadable' if held is _ABSENT else _short(held)
        return _Place(None, (
            f'the model at {artifact} was replaced while this session ran (its {ARTIFACT_HASH} '
            f"was {_short(start)}, now {now}): {base.path} is the new model's, left alone"
        ), warn=True)  # fmt: skip
    final = _final_artifact(artifact)
    if final is not None and final.is_dir() and _held(final) == start:
        return _Place(
            adaptation_path(final), f'{artifact} moved to {final}: train completed its run'
        )
    elsewhere = '' if final is None else (
        f', and {final} holds another model' if final.is_dir() else f', nor is it at {final}'
    )  # fmt: skip
    return _Place(None, f'the artifact folder {artifact} is gone{elsewhere}', warn=True)


def _state_folder() -> Path:
    """``$XDG_STATE_HOME/id_learning`` (``~/.local/state/id_learning``): the last fallback."""
    root = os.environ.get('XDG_STATE_HOME') or str(Path.home() / '.local' / 'state')
    return Path(root) / 'id_learning'


def _elsewhere(base: StoredBase) -> list[Path]:
    """Files for a state that cannot go beside its model, nearest first (none overwritten)."""
    name = f'{base.folder.name}.{ADAPTATION_JSON}.{_model_tag(base.model_sha256)}'
    nearest = next((p for p in base.folder.parents if p.is_dir()), None)
    folders = [f for f in (nearest, _state_folder()) if f is not None]
    return [folder / name for folder in folders]


def save_state(
    loop: AdaptationLoop, joints: tuple[str, ...], base: StoredBase
) -> tuple[bool, Path, str] | None:
    """Write the loop's state if this session learnt: (is a warning, path, what), or None.

    None: no accepted update this session, so the stored state is left as it was. Otherwise the
    state goes where its model is (the module's docstring); in the model's own file a file
    that could not be continued from is moved aside first, and the new state is written to a
    temporary file, flushed to disk and renamed over the old one. A warning: the state could
    not go beside its model and went elsewhere, said why.

    Raises:
        OSError: the state could be written nowhere (names each place tried and why).
    """
    updates = loop.session_updates
    if updates == 0:
        return None
    state = loop.state(joints) | {
        ARTIFACT_HASH: base.model_sha256,
        'artifact': str(base.folder),
        'mode': _mode(loop),
        'updates': updates,
        'updates_total': base.updates_before + updates,
        'continued_from_earlier_sessions': base.problem is None and base.updates_before > 0,
    }
    what = (
        f'{updates} updates of this session on top of {base.updates_before} earlier '
        f'({state["updates_total"]} in all)'
    )
    place, tried = _placement(base), []
    if place.own is not None:
        path = place.own
        try:
            with _folder_locked(path.parent):
                if _changed(base, path):
                    side, note = _beside(path, base, state)
                    _saved(loop, base, side, side=True)
                    return True, side, what + note
                moved = ''
                if base.problem is not None and path.exists():
                    aside = _free(path.with_name(f'{path.name}.{base.aside_tag}'))
                    path.replace(aside)
                    moved = f'; the file it could not continue from is kept as {aside.name}'
                _write(path, state)
                _saved(loop, base, path, side=False)
        except OSError as err:
            tried.append(f'{path} ({err.strerror or err})')
            place = _Place(None, f'{path} could not be written ({err.strerror or err})', True)
        else:
            return place.warn, path, what + moved + (f'; {place.why}' if place.why else '')
    learnt_on = f'learnt on the model with {ARTIFACT_HASH} {_short(base.model_sha256)}'
    for wanted in _elsewhere(base):
        path = wanted
        try:
            wanted.parent.mkdir(parents=True, exist_ok=True)
            path = _free(wanted)
            _write(path, state)
        except OSError as err:
            tried.append(f'{path} ({err.strerror or err})')
            continue
        return True, path, f'{what}, {learnt_on}, not beside it: {place.why}'
    raise OSError(f'{place.why}; {learnt_on}; could not be written to {", ".join(tried)}')
