"""The adaptation's learnt values across predictor sessions: ``<artifact>.adaptation.json``.

A session starts from what the file holds (when it was written for the same joints and mode)
and writes back only when it learnt something: a session that accepted no update (NaN currents,
a reference always stale) leaves the file as it was, so that it never erases what an earlier one
learnt. Writing is atomic (a temporary file, flushed to disk, then renamed over the old one). A
file that cannot be continued from is never overwritten: it is kept as ``<file>.previous`` (or
``.previous.N``) before a new one is written. It cannot be continued from when it is unreadable,
for other joints, mode or base parameters, or holds a value the adaptation never reaches online:
not finite, beyond the limits it keeps its estimate and error scale within (``ESTIMATE_PRIOR_STDS``
prior standard deviations, the torque limit), an applied correction beyond its bound, or an error
scale of 0 (which would gate every sample); the reason names the key, the joint and the value.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from id_learning.config_io import read_capped
from id_learning.errors import ConfigError

__all__ = [
    'ADAPTATION_JSON',
    'COLUMNS',
    'ESTIMATE_PRIOR_STDS',
    'AdaptationLoop',
    'StoredBase',
    'adaptation_path',
    'load_base',
    'save_state',
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
    """

    path: Path
    updates_before: int = 0
    problem: str | None = None
    found: bool = True

    def line(self) -> tuple[bool, str] | None:
        """(is a warning, what the session starts from) for the log; None: there was no file."""
        if self.problem is not None:
            return True, (
                f'adaptation starts from zero: {self.path} cannot be continued from '
                f'({self.problem}); it is kept as {self.path.name}.previous if this session '
                'learns'
            )
        if not self.found:
            return None
        return False, (
            f'adaptation continues from {self.path} ({self.updates_before} updates in earlier '
            'sessions)'
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


def load_base(loop: AdaptationLoop, artifact: Path | str, joints: tuple[str, ...]) -> StoredBase:
    """Continue the loop from the stored file when it fits; what was found (no file: zero)."""
    path = adaptation_path(artifact)
    if not path.exists():
        return StoredBase(path, found=False)
    try:
        state = json.loads(
            read_capped(path, 'adaptation state', MAX_STATE_BYTES, regular=True).decode('utf-8')
        )
        if not isinstance(state, dict):
            raise ValueError('not a JSON object')
        _restore(loop, state, joints)
        before = int(state.get('updates_total', state.get('updates')) or 0)
    except (ConfigError, ValueError, TypeError) as err:  # JSONDecodeError is a ValueError
        return StoredBase(path, problem=str(err) or type(err).__name__)
    return StoredBase(path, updates_before=before)


def _aside(path: Path) -> Path:
    """A free name beside ``path`` for a file that must not be overwritten."""
    candidate = path.with_name(f'{path.name}.previous')
    k = 1
    while candidate.exists():
        candidate = path.with_name(f'{path.name}.previous.{k}')
        k += 1
    return candidate


def save_state(
    loop: AdaptationLoop, joints: tuple[str, ...], base: StoredBase
) -> tuple[Path, str] | None:
    """Write the loop's state over ``base.path`` if this session learnt; (path, what) or None.

    None: no accepted update this session, so the stored state is left as it was. Otherwise a
    file that could not be continued from is moved aside first, and the new state is written
    to a temporary file, flushed to disk and renamed over the old one.

    Raises:
        OSError: the file could not be written (the old one is then as it was).
    """
    updates = loop.session_updates
    if updates == 0:
        return None
    state = loop.state(joints) | {
        'mode': _mode(loop),
        'updates': updates,
        'updates_total': base.updates_before + updates,
        'continued_from_earlier_sessions': base.problem is None and base.updates_before > 0,
    }
    path = base.path
    moved = ''
    if base.problem is not None and path.exists():
        aside = _aside(path)
        path.replace(aside)
        moved = f'; the file it could not continue from is kept as {aside.name}'
    tmp = path.with_name(f'.{path.name}.tmp')
    with tmp.open('w', encoding='utf-8') as stream:
        stream.write(json.dumps(state, indent=2))
        stream.flush()
        os.fsync(stream.fileno())
    tmp.replace(path)
    what = (
        f'{updates} updates of this session on top of {base.updates_before} earlier '
        f'({state["updates_total"]} in all){moved}'
    )
    return path, what
