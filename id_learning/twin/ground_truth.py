"""Read the ground truth the twin writes beside a bag; a damaged file is an error naming it."""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.errors import DatasetError
from id_learning.twin.simulate import GROUND_TRUTH_ARRAYS, GROUND_TRUTH_JSON

__all__ = ['GroundTruth', 'read_ground_truth']


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
