"""A closed terminal (SIGHUP) stops a command as SIGTERM does: one line, cleaned up, 129.

The probe's B44: SIGHUP's default ended ``id-learning`` at once, leaving the hidden folder of a
half-written bag and no line.
"""

from __future__ import annotations

import signal
from pathlib import Path

from dataset.test_import_interrupted import _half_written, _import, log
from record.hangup import hangup_at_default
from test_interrupts import _stop

from id_learning.staged_bag import staging_folder

__all__ = ['log']  # the fixture, imported to be found here


def test_an_import_hung_up_while_writing_leaves_no_bag_and_says_so(
    log: tuple[Path, Path], tmp_path: Path
) -> None:
    out = tmp_path / 'bag'
    with hangup_at_default():
        process = _half_written(_import(log, out))
    status, lines = _stop(process, signal.SIGHUP)
    assert status == 128 + signal.SIGHUP, lines  # before the fix: -1, killed by the signal
    assert not any('Traceback' in line for line in lines), lines
    assert lines[-1] == f'id-learning import: hung up (SIGHUP); nothing was written to {out}'
    assert not out.exists()
    assert not staging_folder(out).exists()  # cleaned up, as after SIGTERM
    assert sorted(path.name for path in tmp_path.iterdir()) == ['log.csv', 'map.yaml']
