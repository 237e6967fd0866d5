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

from id_learning.config_io import read_capped, special_kind
from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.recording import write_recording
from id_learning.dataset.statistics import estimate_noise
from id_learning.errors import DatasetError
from id_learning.output_kinds import OutputError, os_reason
from id_learning.twin.simulate import (
    GROUND_TRUTH_ARRAYS,
    GROUND_TRUTH_JSON,
    TWIN_CONFIG_COPY,
    TwinConfig,
    TwinResult,
)

__all__ = [
    'NOISE_ALLOWANCE',
    'GroundTruth',
    'read_ground_truth',
    'read_noise_free_torque',
    'write_twin_output',
]

_LOG = logging.getLogger(__name__)

#: The largest ground_truth.json read [bytes]: the twin's parameters, noise and excitation take
#: about 40 KiB (a long excitation a few hundred); a file of megabytes was put there by hand.
MAX_GROUND_TRUTH_JSON_BYTES = 16 * 2**20


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
        DatasetError: a ground-truth file is no regular file (``_refuse_special``),
            ground_truth.json is over its cap or not a JSON mapping, or ground_truth.npz is
            missing, unreadable, lacks the target's array or holds other stamps (names the file).
    """
    folder = Path(bag)
    json_path, arrays_path = folder / GROUND_TRUTH_JSON, folder / GROUND_TRUTH_ARRAYS
    _refuse_special(folder)
    if not json_path.is_file():
        return None
    try:
        info = json.loads(_json_text(json_path))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
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
    result: TwinResult,
    config: TwinConfig,
    out: Path | str,
    *,
    overwrite: bool = False,
    place: Path | str | None = None,
) -> Path:
    """Write the bag plus ground truth (JSON parameters, NPZ noise-free torques) and the config.

    The ground-truth files sit inside the bag folder, where rosbag2 tools ignore them. ``place``:
    the folder the bag will be read in, where it is written elsewhere first (``staged_bag``);
    the config copy's relative paths are written for it (default: ``out``).
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
        home = Path(place or out).resolve()  # where the copy will be read: its paths from there
        raw['robot'] = os.path.relpath(Path(config.robot_file).resolve(), home)
        if config.excitation.file is not None:  # read beside the copy as beside the original
            designed = os.path.relpath(Path(config.excitation.file).resolve(), home)
            raw['excitation'] = {**(raw.get('excitation') or {}), 'file': designed}
        extras[2].write_text(yaml.safe_dump(raw, sort_keys=False), encoding='utf-8')
    except OSError as err:
        for path in extras:  # half a ground truth would be read as the whole
            path.unlink(missing_ok=True)
        state = (
            'the new bag is not kept'  # written beside its place: the writer discards it
            if place is not None
            else 'the bag is complete, its ground truth is not there'
        )
        raise OutputError(
            f'{err.filename or out}: {os_reason(err)} (writing the ground truth beside the '
            f'bag; {state})'
        ) from err
    _LOG.info('twin: wrote %d samples to %s', result.recording.n_samples, out)
    return out


#: A ground truth belongs to a recording when the recorded labels differ from its noise-free
#: torque by the sensor noise alone: the twin records clean torque plus white noise (and the
#: current quantisation), so their difference has the labels' own white-noise level. Its RMS
#: over N samples scatters by about 1 / sqrt(2 N) (a few % here); this factor leaves room for
#: that and for an under-estimated noise level, while the ground truth of another motion is
#: off by the torque itself (ten times the noise and more).
NOISE_ALLOWANCE = 2.0


def read_noise_free_torque(bag: Path | str, dataset: Dataset) -> tuple[np.ndarray | None, str]:
    """The twin's noise-free label torque at a preprocessed recording's stamps, if it is its own.

    A ground truth beside the bag is used only when it provably belongs to the recording: it
    holds every one of its stamps, ground_truth.json describes the same simulation as the
    arrays, and the labels differ from it by no more than the sensor noise
    (``NOISE_ALLOWANCE`` times the larger of the noise the twin states and the labels' own
    white level above the motion's band). Otherwise it is ignored, with the reason.

    Args:
        bag: the bag folder the dataset was loaded from.
        dataset: one preprocessed segment of it (its target, stamps and raw labels).

    Returns:
        ((N, n) noise-free tau_u or joint torque [N*m], '') for a ground truth of this
        recording; (None, '') for a bag without one; (None, why) for one ignored: the reason
        names the file, the mismatch and what is missing because of it.

    Raises:
        DatasetError: a ground-truth file is no regular file (``_refuse_special``),
            ground_truth.json is over its cap, or ground_truth.npz is unreadable or lacks the
            target's arrays.
    """
    folder = Path(bag)
    path, json_path = folder / GROUND_TRUTH_ARRAYS, folder / GROUND_TRUTH_JSON
    _refuse_special(folder)
    ignored = 'ignored: no label-noise floor and no errors against the truth for this bag'
    if not path.is_file():
        if json_path.is_file():
            return None, f'{json_path}: has no {path.name} beside it; {ignored}'
        return None, ''
    key = 'tau_u_clean' if dataset.target == 'motor' else 'tau_joint_clean'
    try:
        with np.load(path) as arrays:
            stamps, clean = np.asarray(arrays['stamps_ns']), np.asarray(arrays[key])
            motor = np.asarray(arrays['tau_u_clean']) if 'tau_u_clean' in arrays.files else None
    except (KeyError, OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise DatasetError(
            f'{path}: unreadable ground truth ({type(err).__name__}: {err})'
        ) from err
    info = _json_object(json_path)
    order = _column_order(info, dataset.joints)
    mismatch = _stamp_mismatch(stamps, clean, dataset) or _json_mismatch(info, motor)
    if mismatch:
        return None, f'{path} does not belong to this recording: {mismatch}; {ignored}'
    torque: np.ndarray = clean[np.searchsorted(stamps, dataset.stamps_ns)][:, order]
    mismatch = _label_mismatch(torque.astype(float), dataset, _stated_noise(info, dataset, order))
    if mismatch:
        factors = _label_factors(torque.astype(float), dataset)
        if factors:  # the labels are a multiple of the truth: the drive constants, not the file
            return None, (
                f'{path} holds every stamp of this recording{_agreeing(info)}, yet {mismatch}: '
                f'{_drive_cause(dataset)}; per joint the labels are about this multiple of the '
                f'truth: {factors}; {ignored}'
            )
        return None, (
            f'{path} does not belong to this recording, or its labels are computed otherwise: '
            f'{mismatch}: {_drive_cause(dataset)} (the ground truth of another simulation or '
            f'another motion); {ignored}'
        )
    return torque.astype(float), ''


def _stamp_mismatch(stamps: np.ndarray, clean: np.ndarray, dataset: Dataset) -> str:
    """Why the arrays cannot hold the recording's samples ('' when they hold every stamp)."""
    n = len(dataset.joints)
    if stamps.ndim != 1 or clean.shape != (len(stamps), n):
        return (
            f'it holds {clean.shape} noise-free torques for {stamps.shape} stamps, expected '
            f'(samples, {n}) for the joints {", ".join(dataset.joints)}'
        )
    wanted = np.asarray(dataset.stamps_ns)
    rows = np.minimum(np.searchsorted(stamps, wanted), max(len(stamps) - 1, 0))
    missing = np.flatnonzero(stamps[rows] != wanted) if len(stamps) else np.arange(len(wanted))
    if not missing.size:
        return ''
    span = f'{int(stamps[0])} to {int(stamps[-1])} ns' if len(stamps) else 'no stamp'
    return (
        f'it lacks {missing.size} of the {len(wanted)} sample stamps (the first at sample '
        f'{int(missing[0])}, {int(wanted[missing[0]])} ns; it covers {span}, '
        f'{len(stamps)} samples)'
    )


def _column_order(info: dict[str, Any] | None, joints: tuple[str, ...]) -> list[int]:
    """The arrays' columns in the dataset's joint order (the twin's order, as the JSON names it).

    The twin's order where the JSON does not name the same joints (a mismatch is then found).
    """
    names = info.get('joints') if info else None
    if isinstance(names, list) and sorted(map(str, names)) == sorted(joints):
        return [[str(x) for x in names].index(j) for j in joints]
    return list(range(len(joints)))


def _refuse_special(folder: Path) -> None:
    """Refuse a ground-truth file beside a bag that is no regular file (a FIFO, a device, ...).

    The twin writes both as files: a FIFO there would block the read, a link to a device
    (``/dev/zero``) never end. Missing files pass (the readers say what that means).

    Raises:
        DatasetError: names the file and what it is.
    """
    for name in (GROUND_TRUTH_JSON, GROUND_TRUTH_ARRAYS):
        if (kind := special_kind(folder / name)) is not None:
            raise DatasetError(
                f'{folder / name}: {kind}, not a regular file; the twin writes its ground truth '
                'as files: remove it or re-run simulate'
            )


def _json_text(path: Path) -> str:
    """ground_truth.json's text, read whole under ``MAX_GROUND_TRUTH_JSON_BYTES``.

    Raises:
        DatasetError: unreadable, no regular file or over the cap (names the file).
        UnicodeDecodeError: not UTF-8.
    """
    data = read_capped(
        path, 'twin ground truth', MAX_GROUND_TRUTH_JSON_BYTES, regular=True, error=DatasetError
    )
    return data.decode('utf-8')


def _json_object(path: Path) -> dict[str, Any] | None:
    """ground_truth.json as a mapping, or None (missing or damaged: its noise is not used).

    Raises:
        DatasetError: no regular file, or over its cap (``_json_text``).
    """
    if not path.exists():
        return None
    try:
        info = json.loads(_json_text(path))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    return info if isinstance(info, dict) else None


def _json_mismatch(info: dict[str, Any] | None, tau_u_clean: np.ndarray | None) -> str:
    """Why ground_truth.json describes another simulation than the arrays ('' when the same).

    The JSON states the RMS of every joint's noise-free tau_u; the arrays hold it (as float32).
    """
    stated = _vector(info, 'tau_u_clean_rms_nm') if info else None
    if stated is None or tau_u_clean is None:
        return ''
    motor = np.asarray(tau_u_clean, dtype=float)
    if motor.ndim != 2 or len(stated) != motor.shape[1] or not len(motor):
        return ''
    held = np.sqrt(np.mean(motor**2, axis=0))
    if np.allclose(held, stated, rtol=1e-4, atol=1e-3):
        return ''
    j = int(np.argmax(np.abs(held - stated)))
    names = info.get('joints') if info else None
    named = isinstance(names, list) and len(names) == len(held)
    name = str(names[j]) if named and names else f'joint #{j + 1}'
    return (
        f'the {GROUND_TRUTH_JSON} beside it states an RMS noise-free tau_u of {stated[j]:.4g} '
        f'N*m for {name}, the arrays hold {held[j]:.4g}: the two files are of different '
        'simulations'
    )


def _label_mismatch(torque: np.ndarray, dataset: Dataset, stated: np.ndarray | None) -> str:
    """Why the labels are not the noise-free torque plus sensor noise ('' when they are)."""
    residual = np.asarray(dataset.tau_raw, dtype=float) - torque
    off = np.sqrt(np.mean(residual**2, axis=0))
    noise = estimate_noise(
        dataset.tau_raw, dataset.cutoff_hz, dataset.period_s, dataset.filter_order
    ).raw_std_nm
    if stated is not None:
        noise = np.maximum(noise, stated)
    # float32 storage rounds the torque by ~1e-7 of its size
    allowed = NOISE_ALLOWANCE * noise + 1e-6 * (np.max(np.abs(torque), axis=0) + 1.0)
    bad = ~(off <= allowed)  # NaN counts as off
    if not bad.any():
        return ''
    j = int(np.argmax(np.where(bad, off / allowed, -np.inf)))
    worst = int(np.argmax(np.abs(residual[:, j])))
    return (
        f'the labels differ from its noise-free torque by {off[j]:.3g} N*m RMS on '
        f'{dataset.joints[j]} (up to {residual[worst, j]:.3g} at sample {worst}, '
        f'{int(dataset.stamps_ns[worst])} ns), where sensor noise of {noise[j]:.3g} N*m allows '
        f'{allowed[j]:.3g}'
    )


def _agreeing(info: dict[str, Any] | None) -> str:
    """' and its ground_truth.json agrees with it' when there is one (it was compared)."""
    return f' and its {GROUND_TRUTH_JSON} agrees with it' if info is not None else ''


def _drive_cause(dataset: Dataset) -> str:
    """What computes labels that disagree with the twin's noise-free torque, and what to check."""
    if dataset.target == 'motor':
        return (
            "the labels computed with this robot config's drive constants (gear_ratio x "
            "torque_constant x current) disagree with the twin's noise-free torque: check the "
            "robot config's drive constants and the currents' unit, or the recording is of "
            'another simulation'
        )
    return (
        "the joint-torque labels disagree with the twin's noise-free joint torque: check the "
        "torque sensors' unit and sign, or the recording is of another simulation"
    )


def _label_factors(torque: np.ndarray, dataset: Dataset) -> str:
    """'joint f, ...' when the labels are a multiple of the truth on every joint, else ''.

    Per joint the least-squares factor f of labels = f x truth; it is named when it explains
    90 % of the labels on every joint (a wrong gear_ratio, torque_constant or current unit).
    """
    labels = np.asarray(dataset.tau_raw, dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        factor = np.sum(labels * torque, axis=0) / np.sum(torque**2, axis=0)
        left = np.sum((labels - factor * torque) ** 2, axis=0) / np.sum(labels**2, axis=0)
    if not (np.all(np.isfinite(factor)) and np.all(left <= 0.1)):
        return ''
    return ', '.join(f'{j} {f:.4g}' for j, f in zip(dataset.joints, factor, strict=True))


def _stated_noise(
    info: dict[str, Any] | None, dataset: Dataset, order: list[int]
) -> np.ndarray | None:
    """The per-joint label noise [N*m] ground_truth.json states (dataset order), or None."""
    noise = info.get('noise') if info else None
    if not isinstance(noise, dict):
        return None
    n = len(dataset.joints)
    if dataset.target == 'motor':
        parts = [
            _vector(noise, 'current_noise_std_as_tau_u_nm'),
            _vector(noise, 'current_quantisation_std_as_tau_u_nm'),
        ]
    else:
        parts = [_vector(noise, 'joint_torque_noise_std')]
    if any(p is None or p.shape != (n,) for p in parts):
        return None
    out: np.ndarray = np.sqrt(sum(p**2 for p in parts if p is not None))
    return out[order]


def _vector(mapping: dict[str, Any], key: str) -> np.ndarray | None:
    """A finite float vector under ``key``, or None when absent or not one."""
    try:
        value = np.asarray(mapping.get(key), dtype=float)
    except (TypeError, ValueError):
        return None
    return value if value.ndim == 1 and np.all(np.isfinite(value)) else None
