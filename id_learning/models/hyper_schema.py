"""The declared type and range of every hyper-parameter, checked before a config is built.

One rule for all model kinds: a value must be of its field's type (int fields take ints, not
bools or floats; floats are finite; bools are bools; strings are strings, whose allowed choices
the config's own ``__post_init__`` names) and within its range here. The ranges bound sizes and
counts so that no fit asks for absurd memory or time, yet leave a demanding user room: 4096
units per layer (the default is 64), 16 layers, 10^6 epochs, 2^20 samples per batch.
"""

from __future__ import annotations

import math
import numbers
import types
from dataclasses import fields
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

import numpy as np

from id_learning.errors import ConfigError

__all__ = ['HYPER_RANGES', 'check_hyper']

_SIZE = (1, 4096)  # units per layer: a 4096-wide MLP is ~16M weights per layer
_LAYERS = (1, 16)
_COUNT = (1, 10**6)  # epochs and patiences
_STRIDE = (1, 10**5)  # a stride past the data leaves no rows; 10^5 samples is 13 min at 125 Hz
_STD = (1e-9, 10.0)  # relative and metric prior standard deviations

#: Per field name (the same name means the same thing in every kind), the closed range
#: [low, high] of a number. A number field missing here is a programming error (test_hyper).
HYPER_RANGES: dict[str, tuple[float, float]] = {
    'width': _SIZE,
    'hidden_size': _SIZE,
    'dissipation_width': _SIZE,
    'depth': _LAYERS,
    'num_layers': _LAYERS,
    'dissipation_depth': _LAYERS,
    'max_epochs': _COUNT,
    'patience': _COUNT,
    'lr_decay_patience': _COUNT,
    'batch_size': (1, 2**20),
    'windows_per_batch': (1, 4096),
    'sequence_length': (1, 10**4),  # 80 s of IPO samples per LSTM window
    'stride': _STRIDE,
    'eval_stride': _STRIDE,
    'seed': (0, 2**32 - 1),  # numpy's and Optuna's generators
    'iterations': (1, 100),
    'joint_rounds': (0, 20),
    'learning_rate': (1e-12, 10.0),
    'weight_decay': (0.0, 10.0),
    'lr_decay': (1e-6, 1.0),
    'energy_balance': (0.0, 1.0),
    'max_seconds': (1e-3, 1e7),  # about 4 months
    'coulomb_velocity': (1e-9, 100.0),  # [rad/s]
    'diagonal_epsilon': (0.0, 1e6),
    'diagonal_shift': (0.0, 1e6),
    'mass_rel_std': _STD,
    'com_std_m': _STD,
    'gain_std': _STD,
}


_TYPE_NAMES = {
    int: 'an integer',
    float: 'a finite number',
    bool: 'true or false',
    str: 'a string',
    type(None): 'null',
}


def _allowed(hint: Any) -> tuple[type, ...]:
    """The plain types a field's annotation allows (``float | None`` -> (float, NoneType))."""
    if get_origin(hint) is Literal:
        return tuple({type(arg) for arg in get_args(hint)})
    if get_origin(hint) in (Union, types.UnionType):
        return tuple(t for arg in get_args(hint) for t in _allowed(arg))
    return (hint,) if isinstance(hint, type) else (object,)


def _checked(where: str, value: Any, allowed: tuple[type, ...]) -> Any:
    """``value`` if it is of an allowed type (an int where a float is allowed becomes one)."""
    if value is None and type(None) in allowed:
        return None
    if isinstance(value, (bool, np.bool_)):
        ok = bool in allowed
        value = bool(value)
    elif isinstance(value, numbers.Integral):  # numpy's integers too (sweeps, benchmarks)
        ok = int in allowed or float in allowed
        value = int(value) if int in allowed else float(value)
    elif isinstance(value, numbers.Real):
        ok = float in allowed and math.isfinite(value)
        value = float(value)
    else:
        ok = isinstance(value, tuple(t for t in allowed if t is not type(None)))
    if not ok:
        names = ' or '.join(_TYPE_NAMES.get(t, t.__name__) for t in allowed if t is not object)
        raise ConfigError(f'{where}: must be {names}, got {value!r}')
    return value


def check_hyper(kind: str, config_class: type, overrides: dict[str, Any]) -> dict[str, Any]:
    """``overrides`` of ``kind`` checked against their fields' types and ``HYPER_RANGES``.

    Called where every config is made (``registry.make_config``), so that a bad value is refused
    in one line naming ``kind.key`` before a config's own checks compare it, and before any data
    are loaded or any tensor allocated.

    Raises:
        ConfigError: unknown key, wrong type, a NaN or inf, or a value out of range.
    """
    hints = get_type_hints(config_class)
    names = {item.name for item in fields(config_class)} - {'kind'}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ConfigError(f'{kind}: unknown hyper-parameter(s) {unknown}; known: {sorted(names)}')
    out = {}
    for key, given in overrides.items():
        where = f'{kind}.{key}'
        value = _checked(where, given, _allowed(hints[key]))
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            low, high = HYPER_RANGES[key]
            if not low <= value <= high:
                raise ConfigError(f'{where}: must be in [{low:g}, {high:g}], got {value!r}')
        out[key] = value
    return out
