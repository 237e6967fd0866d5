"""The memory this machine has free, for inputs that must not be read beyond it."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ['available_memory_bytes']


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
