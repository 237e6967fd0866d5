"""Strict YAML helpers shared by every config loader: unknown keys and bad values name the key."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from id_learning.errors import ConfigError

__all__ = ['check_keys', 'float_vector', 'load_yaml_mapping', 'readonly']


def load_yaml_mapping(path: Path) -> dict[str, Any]:
    """Read a YAML file whose top level is a mapping.

    Raises:
        ConfigError: the file is missing, is not valid YAML, or is not a mapping.
    """
    try:
        text = Path(path).read_text(encoding='utf-8')
    except OSError as err:
        raise ConfigError(f'{path}: cannot read config file: {err.strerror}') from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ConfigError(f'{path}: not valid YAML: {err}') from err
    if not isinstance(data, dict):
        raise ConfigError(
            f'{path}: expected a mapping at the top level, got {type(data).__name__}'
        )
    return data


def check_keys(
    data: Mapping[str, Any],
    allowed: Sequence[str],
    where: str,
    required: Sequence[str] = (),
) -> None:
    """Reject unknown and missing keys, naming them and where they are.

    Raises:
        ConfigError: a key is unknown or a required key is missing.
    """
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ConfigError(f'{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}')
    missing = [key for key in required if key not in data]
    if missing:
        raise ConfigError(f'{where}: missing required key(s) {missing}')


def readonly(array: np.ndarray) -> np.ndarray:
    """Return the array marked read-only, so frozen configs stay frozen."""
    array.flags.writeable = False
    return array


def float_vector(
    value: Any,
    where: str,
    length: int,
    *,
    minimum: float | None = None,
    exclusive_minimum: bool = False,
) -> np.ndarray:
    """Convert a scalar or list into a read-only float vector of the given length.

    A scalar is broadcast to every joint.

    Raises:
        ConfigError: wrong length, non-numeric or non-finite entries, or a value below the minimum.
    """
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise ConfigError(f'{where}: expected numbers, got {value!r}') from err
    if array.ndim == 0:
        array = np.full(length, float(array))
    if array.shape != (length,):
        raise ConfigError(f'{where}: expected {length} values (one per joint), got {value!r}')
    if not np.all(np.isfinite(array)):
        raise ConfigError(f'{where}: values must be finite, got {value!r}')
    if minimum is not None:
        bad = array <= minimum if exclusive_minimum else array < minimum
        if np.any(bad):
            relation = '>' if exclusive_minimum else '>='
            raise ConfigError(f'{where}: every value must be {relation} {minimum}, got {value!r}')
    return readonly(array)
