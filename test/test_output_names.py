"""Output paths the file system cannot hold are one clear line; the names that fit are written.

Property-based: whatever the names (any characters, any length, any depth), every way an output
is opened (result folder, bag, file, sweep folder, lock) either refuses before touching the disk,
in one line naming the path, the too-long name and the option, or writes it, ``.partial``,
``.lock`` and a replaced result's ``.replaced-<pid>`` included.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.outputs import (
    NAME_RESERVE,
    OutputError,
    check_bag_output,
    check_file_output,
    check_output,
    check_target,
    output_lock,
    refuse_long_names,
    result_folder,
)

#: Letters of one to four bytes in UTF-8: a name's length in bytes is what the file system limits.
LETTERS = st.sampled_from(['a', 'Z', '_', '-', '.', 'é', 'ß', '€', '中', '🙂', ' '])
#: Names around the limits of a 255-byte file system (and its last name, 20 bytes less).
NEAR_LIMITS = st.builds(
    lambda size, tail: 'n' * size + tail,
    st.one_of(st.integers(228, 240), st.integers(248, 260)),
    st.sampled_from(['', 'é', '€', '🙂']),
)
NAMES = st.one_of(
    st.text(LETTERS, min_size=1, max_size=300).filter(lambda name: name not in ('.', '..')),
    NEAR_LIMITS,
)


def _name_max(folder: Path) -> int:
    return os.pathconf(folder, 'PC_NAME_MAX')


def _too_long(parts: list[str], name_max: int) -> bool:
    sizes = [len(os.fsencode(part)) for part in parts]
    return any(size > name_max for size in sizes) or sizes[-1] > name_max - NAME_RESERVE


def _open_result(out: Path, option: str) -> None:
    with result_folder(out, command='test', option=option) as folder:
        (folder.work / 'run.json').write_text('{}')
    with result_folder(out, command='test', option=option, force=True) as folder:  # replaced
        (folder.work / 'run.json').write_text('{}')


def _open_lock(out: Path, option: str) -> None:
    check_target(out, option=option)
    out.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(out, option=option):
        pass


#: Every way a command opens an output, with the option its message names.
OPENERS: dict[str, Callable[[Path, str], object]] = {
    'result_folder': _open_result,
    'check_output': lambda out, option: check_output(out, option=option),
    'check_bag_output': lambda out, option: check_bag_output(out, option=option),
    'check_file_output': lambda out, option: check_file_output(out, option=option),
    'output_lock': _open_lock,
}


@pytest.mark.parametrize('opener', sorted(OPENERS))
@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(parts=st.lists(NAMES, min_size=1, max_size=3))
def test_any_name_too_long_is_one_line_before_the_disk_is_touched_and_others_are_written(
    opener: str, parts: list[str]
) -> None:
    option = 'output:=PATH' if opener == 'output_lock' else '--opt'
    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder)
        out = base.joinpath(*parts)
        if _too_long(parts, _name_max(base)):
            with pytest.raises(OutputError) as refused:
                OPENERS[opener](out, option)
            message = str(refused.value)
            assert '\n' not in message
            assert message.startswith(f'{out}: file name too long: ')
            assert message.endswith(f'choose a shorter {option}')
            assert list(base.iterdir()) == []  # not even a parent folder
        else:
            OPENERS[opener](out, option)  # no OSError: every name made from it fits too
            if opener == 'result_folder':
                assert (out / 'run.json').is_file()
                assert sorted(p.name for p in out.parent.iterdir()) == [out.name]


def test_the_whole_path_too_long_is_one_line(tmp_path: Path) -> None:
    path_max = os.pathconf(tmp_path, 'PC_PATH_MAX')
    out = tmp_path.joinpath(*['d' * 200] * (path_max // 200 + 1))
    with pytest.raises(OutputError, match=r'path too long: \d+ bytes .* choose a shorter --out$'):
        check_target(out)
    assert list(tmp_path.iterdir()) == []


def test_a_name_limit_the_file_system_has_is_what_is_checked(tmp_path: Path) -> None:
    name_max = _name_max(tmp_path)
    refuse_long_names(tmp_path / ('n' * (name_max - NAME_RESERVE)))
    refuse_long_names(tmp_path / ('n' * name_max) / 'leaf')
    with pytest.raises(OutputError, match=f'is {name_max + 1} bytes, at most {name_max} '):
        refuse_long_names(tmp_path / ('n' * (name_max + 1)) / 'leaf')
    with pytest.raises(OutputError, match=r'\(the file system takes \d+; 20 are kept'):
        refuse_long_names(tmp_path / ('n' * (name_max - NAME_RESERVE + 1)))
