"""SIGHUP at its default in the programs a test starts, as under a terminal or an ssh session.

A suite started with ``nohup`` passes SIGHUP on ignored, and a program leaves an ignored SIGHUP
ignored (it was meant to outlive its terminal): the tests of a hang-up give their children the
default a terminal's job has.
"""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Iterator


@contextlib.contextmanager
def hangup_at_default() -> Iterator[None]:
    """SIGHUP at its default while the block starts processes (they inherit only SIG_IGN)."""
    before = signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        yield
    finally:
        signal.signal(signal.SIGHUP, before)
