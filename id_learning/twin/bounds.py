"""How long a simulation may be: a stated maximum, and what the machine's memory holds.

The twin keeps every sample in memory until the bag is written (the motion, each torque
component, the currents and the ground truth): about ``BYTES_PER_SAMPLE_JOINT`` bytes per
sample and joint, measured on the default twin (8 ms IPO period, 6 joints: 480 s peak at 209 MB,
60 s at 117 MB, so 300 B per sample and joint, with a margin on top). A duration is refused
above ``MAX_DURATION_S`` or where it would need more than ``MEMORY_SHARE`` of the memory
available, before any work starts, instead of swapping for hours or being killed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from id_learning.config_io import finite_number
from id_learning.errors import ConfigError
from id_learning.record.excitation import ExcitationConfig, check_bandwidth

__all__ = [
    'BYTES_PER_SAMPLE_JOINT',
    'MAX_DURATION_S',
    'MEMORY_SHARE',
    'available_memory_bytes',
    'check_duration',
    'check_excitation',
]

#: The longest excitation the twin simulates [s]: one day of recording.
MAX_DURATION_S = 86_400.0
#: Memory the twin holds per sample and joint until the bag is written [bytes].
BYTES_PER_SAMPLE_JOINT = 384
#: The share of the available memory one simulation may take.
MEMORY_SHARE = 0.5


def available_memory_bytes() -> int | None:
    """The memory available to a new allocation [bytes] (Linux MemAvailable), or None."""
    try:
        for line in Path('/proc/meminfo').read_text(encoding='ascii').splitlines():
            if line.startswith('MemAvailable:'):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf('SC_AVPHYS_PAGES') * os.sysconf('SC_PAGE_SIZE')
    except (AttributeError, OSError, ValueError):
        return None


def check_duration(
    duration_s: object, period_s: float, n_joints: int, where: str, available: int | None = None
) -> float:
    """``duration_s`` as a float when the twin can simulate it here.

    Args:
        duration_s: the excitation's length [s].
        period_s: the robot's IPO period [s].
        n_joints: the robot's joint count.
        where: the key or option named in errors (``excitation.duration_s``, ``--duration``).
        available: memory available [bytes]; None reads it from the system.

    Raises:
        ConfigError: not a finite number in (0, MAX_DURATION_S], or more samples than
            MEMORY_SHARE of the available memory holds (names the bound in seconds).
    """
    duration = finite_number(duration_s, where, low=0.0, high=MAX_DURATION_S, low_open=True)
    available = available_memory_bytes() if available is None else available
    if available is None:
        return duration
    per_second = n_joints * BYTES_PER_SAMPLE_JOINT / period_s
    need = (duration / period_s + 1) * n_joints * BYTES_PER_SAMPLE_JOINT
    budget = MEMORY_SHARE * available
    if need > budget:
        raise ConfigError(
            f'{where}: {duration:g} s at the {period_s * 1e3:g} ms IPO period would need about '
            f'{need / 2**30:.1f} GiB, more than {MEMORY_SHARE:.0%} of the '
            f'{available / 2**30:.1f} GiB of memory available: at most '
            f'{max(budget / per_second - period_s, 0.0):.0f} s fit on this machine; simulate '
            'shorter runs'
        )
    return duration


#: The excitation's numbers and their ranges: (low, high, low_open, integer).
_EXCITATION_RANGES: dict[str, tuple[float, float | None, bool, bool]] = {
    'base_frequency_hz': (0.0, None, True, False),
    'harmonics': (1, 10, False, True),
    'position_fraction': (0.0, 1.0, True, False),
    'velocity_fraction': (0.0, 1.0, True, False),
    'acceleration_fraction': (0.0, 1.0, True, False),
    'rest_s': (0.0, MAX_DURATION_S, False, False),
}


def check_excitation(
    data: dict[str, Any], period_s: float, n_joints: int, where: str
) -> dict[str, Any]:
    """The excitation section with each number checked finite and in range (home aside).

    Raises:
        ConfigError: names the key (``where.key``), the value and the allowed range; harmonics
            at or above the IPO period's Nyquist frequency (``check_bandwidth``); a duration
            beyond what ``check_duration`` allows.
    """
    checked = dict(data)
    for key, (low, high, low_open, integer) in _EXCITATION_RANGES.items():
        if key in data:
            checked[key] = finite_number(
                data[key], f'{where}.{key}', low=low, high=high, low_open=low_open, integer=integer
            )
    defaults = ExcitationConfig()
    check_bandwidth(
        checked.get('base_frequency_hz', defaults.base_frequency_hz),
        checked.get('harmonics', defaults.harmonics),
        period_s,
        where,
    )
    if 'duration_s' in data:
        checked['duration_s'] = check_duration(
            data['duration_s'], period_s, n_joints, f'{where}.duration_s'
        )
    return checked
