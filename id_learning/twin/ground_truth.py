"""Read the ground truth the twin writes beside a bag; a damaged file is an error naming it."""

from __future__ import annotations

import json
import logging
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from id_learning.dataset.recording import write_recording
from id_learning.errors import DatasetError
from id_learning.output_kinds import OutputError, os_reason
from id_learning.twin.simulate import (
    GROUND_TRUTH_ARRAYS,
    GROUND_TRUTH_JSON,
    TWIN_CONFIG_COPY,
    TwinConfig,
    TwinResult,
)

__all__ = ['GroundTruth', 'read_ground_truth', 'read_noise_free_torque', 'write_twin_output']

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """A twin bag's ground truth.

    Attributes:
        info: the parsed ground_truth.json (a mapping).
        tau_clean: (N, n) noise-free label torque [N*m] of the requested target.
    """

    info: dict[str, Any]
    tau_clean: np.ndarray


def read_ground_truth(
    bag: Path | str, target: str, stamps_ns: np.ndarray | None = None
) -> GroundTruth | None:
    """The ground truth beside a twin bag, or None when the bag has no ground_truth.json.

    Args:
        bag: a bag folder written by ``write_twin_output``.
        target: 'motor' (tau_u) or 'joint' (joint torque).
        stamps_ns: the recording's stamps [ns]: the ground truth must hold exactly these (one
            copied from another simulation does not); None: not checked.

    Raises:
        DatasetError: ground_truth.json is not a JSON mapping, or ground_truth.npz is missing,
            unreadable, lacks the target's array or holds other stamps (names the file).
    """
    folder = Path(bag)
    json_path, arrays_path = folder / GROUND_TRUTH_JSON, folder / GROUND_TRUTH_ARRAYS
    if not json_path.is_file():
        return None
    try:
        info = json.loads(json_path.read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DatasetError(
            f'{json_path}: cannot read the twin ground truth: {err}; remove the file or '
            're-run simulate'
        ) from None
    if not isinstance(info, dict):
        raise DatasetError(
            f'{json_path}: expected a JSON object (the twin ground truth), '
            f'got {type(info).__name__}'
        )
    key = 'tau_u_clean' if target == 'motor' else 'tau_joint_clean'
    try:
        with np.load(arrays_path) as arrays:
            tau = np.asarray(arrays[key], dtype=float)
            truth_stamps = np.asarray(arrays['stamps_ns']) if 'stamps_ns' in arrays else None
    except FileNotFoundError:
        raise DatasetError(
            f'{arrays_path}: missing beside {json_path.name}; re-run simulate'
        ) from None
    except KeyError:
        raise DatasetError(f'{arrays_path}: has no {key} array; re-run simulate') from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DatasetError(f'{arrays_path}: cannot read the twin ground truth: {err}') from None
    if tau.ndim != 2:
        raise DatasetError(f'{arrays_path}: {key} has shape {tau.shape}, expected (N, joints)')
    if stamps_ns is not None and (
        truth_stamps is None or not np.array_equal(truth_stamps, np.asarray(stamps_ns))
    ):
        raise DatasetError(
            f"{arrays_path}: its stamps are not the recording's ({len(stamps_ns)} samples from "
            f'{int(stamps_ns[0]) if len(stamps_ns) else 0} ns): the ground truth of another '
            'simulation; remove it or re-run simulate'
        )
    return GroundTruth(info=info, tau_clean=tau)


def write_twin_output(
    result: TwinResult, config: TwinConfig, out: Path | str, *, overwrite: bool = False
) -> Path:
    """Write the bag plus ground truth (JSON parameters, NPZ noise-free torques) and the config.

    The ground-truth files sit inside the bag folder, where rosbag2 tools ignore them.
    """
    out = Path(out)
    write_recording(result.recording, out, config.robot.topics, overwrite=overwrite)
    extras = (out / GROUND_TRUTH_JSON, out / GROUND_TRUTH_ARRAYS, out / TWIN_CONFIG_COPY)
    try:
        extras[0].write_text(json.dumps(result.parameters, indent=1) + '\n', encoding='utf-8')
        # Only the two noise-free torques are stored per sample (float32: ~1e-4 N*m
        # resolution); the true motion is exact from the excitation coefficients in the JSON,
        # and the components are summarised there, which keeps the shipped bag small.
        np.savez_compressed(
            extras[1],
            stamps_ns=result.recording.stamps_ns,
            tau_u_clean=result.tau_u_clean.astype(np.float32),
            tau_joint_clean=result.tau_joint_clean.astype(np.float32),
        )
        raw = dict(config.raw)
        raw['robot'] = os.path.relpath(Path(config.robot_file).resolve(), out.resolve())
        extras[2].write_text(yaml.safe_dump(raw, sort_keys=False), encoding='utf-8')
    except OSError as err:
        for path in extras:  # half a ground truth would be read as the whole
            path.unlink(missing_ok=True)
        raise OutputError(
            f'{err.filename or out}: {os_reason(err)} (writing the ground truth beside the '
            'bag; the bag is complete, its ground truth is not there)'
        ) from err
    _LOG.info('twin: wrote %d samples to %s', result.recording.n_samples, out)
    return out


def read_noise_free_torque(
    bag: Path | str, target: str, stamps_ns: np.ndarray
) -> np.ndarray | None:
    """The twin's noise-free label torque at the given stamps, or None for a bag without it.

    Args:
        bag: a bag folder written by ``write_twin_output``.
        target: 'motor' (tau_u) or 'joint' (joint torque).
        stamps_ns: (N,) the stamps wanted (a preprocessed recording's grid).

    Returns:
        (N, n) noise-free tau_u or joint torque [N*m]; None when the bag holds no ground truth
        or it lacks one of the stamps (the recording was edited after the twin wrote it).
    """
    path = Path(bag) / GROUND_TRUTH_ARRAYS
    if not path.is_file():
        return None
    key = 'tau_u_clean' if target == 'motor' else 'tau_joint_clean'
    try:
        with np.load(path) as arrays:
            stamps, clean = arrays['stamps_ns'], arrays[key]
    except (KeyError, OSError, ValueError, zipfile.BadZipFile) as err:
        raise DatasetError(
            f'{path}: unreadable ground truth ({type(err).__name__}: {err})'
        ) from err
    rows = np.searchsorted(stamps, stamps_ns)
    if rows.max(initial=0) >= len(stamps) or not np.array_equal(stamps[rows], stamps_ns):
        return None
    torque: np.ndarray = clean[rows].astype(float)
    return torque
