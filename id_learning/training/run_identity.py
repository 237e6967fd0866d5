"""The run ``evaluate`` and ``closed-loop`` read: recorded in their outputs, checked at the end.

A run folder's path names whatever run is there now: ``train --force --out RUN`` replaces it
whole while an evaluation of it is still scoring the models it loaded. So the outputs record the
run's identity beside its path (``run_identity``: run.json's ``created_unix_s`` and each scored
model's ``artifact_sha256``, read before the models are loaded), and before they are put in place
``check_run_unchanged`` reads it again: a run replaced or changed meanwhile fails the command,
naming what differs, and nothing is presented as complete.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from id_learning.errors import CheckpointError
from id_learning.models.artifact import ARTIFACT_HASH, METADATA_FILE, read_metadata
from id_learning.training.run_folder import MODELS_DIR, RUN_FILE, read_run

__all__ = ['RUN_IDENTITY_KEY', 'check_run_unchanged', 'run_identity']

#: The outputs' key of the run's identity (metrics.json of an evaluation, closed_loop.json).
RUN_IDENTITY_KEY = 'run_identity'


def _held_digest(folder: Path) -> str | None:
    """The ``artifact_sha256`` a model folder's model.json holds now (None: none, unreadable)."""
    try:
        digest = read_metadata(folder / METADATA_FILE).get(ARTIFACT_HASH)
    except CheckpointError:  # loading the model names what is wrong with it
        return None
    return digest if isinstance(digest, str) else None


def run_identity(run_dir: Path, run: dict[str, Any], kinds: Sequence[str]) -> dict[str, Any]:
    """run.json's ``created_unix_s`` and each of ``kinds``' ``artifact_sha256`` (model.json's now).

    ``run``: the run's run.json as read. Take it before the models are loaded: a model replaced
    between the two then differs at the end, never passes unseen.
    """
    return {
        'created_unix_s': run.get('created_unix_s'),
        'artifacts': {kind: _held_digest(Path(run_dir) / MODELS_DIR / kind) for kind in kinds},
    }


def _when(unix_s: Any) -> str:
    """A run.json's creation time for a message."""
    if not isinstance(unix_s, (int, float)):
        return 'an unrecorded time'
    return f'{time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(unix_s))} ({unix_s:.3f})'


def _differences(run_dir: Path, identity: dict[str, Any]) -> list[str]:
    """What differs between ``identity`` and the run folder now, one phrase each."""
    differences = []
    try:
        created = read_run(run_dir).get('created_unix_s')
    except CheckpointError as err:
        differences.append(f'its {RUN_FILE} cannot be read now: {err}')
    else:
        if created != identity['created_unix_s']:
            differences.append(
                f'its {RUN_FILE} was created at {_when(identity["created_unix_s"])}, the one '
                f'there now at {_when(created)}'
            )
    for kind, digest in identity['artifacts'].items():
        held = _held_digest(run_dir / MODELS_DIR / kind)
        if held != digest:
            now = 'is gone or unreadable now' if held is None else f'holds {held[:12]}... now'
            differences.append(
                f'{MODELS_DIR}/{kind} was read with {ARTIFACT_HASH} {str(digest)[:12]}..., {now}'
            )
    return differences


def check_run_unchanged(run_dir: Path, identity: dict[str, Any], command: str) -> None:
    """Refuse the results of ``command`` when the run it read was replaced or changed meanwhile.

    Called once the results are written, before they are put in place: they describe the
    models read at the start (``identity``, from ``run_identity``), which the folder must still
    hold.

    Raises:
        CheckpointError: names the run, each difference (run.json's creation time, a model's
            ``artifact_sha256`` then and now) and that the command must be run again.
    """
    differences = _differences(Path(run_dir), identity)
    if differences:
        raise CheckpointError(
            f'{run_dir}: the run was replaced or changed while {command} read it '
            f'({"; ".join(differences)}; a train --force into it?): the results describe models '
            f'it no longer holds, so none are written; run {command} again'
        )
