"""A dangling link given as an output is named as one, with its target, and what to do for it.

Nothing is written through it (its target may lie on a moved or unmounted disk). A file output
(inspect's --plot) is never told to point the link at a folder.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from id_learning.cli.main import main
from id_learning.outputs import OutputError, check_file_output, check_target


def test_a_dangling_link_given_as_plot_is_named_with_its_target(tmp_path: Path, capsys) -> None:
    link = tmp_path / 'plot.png'
    link.symlink_to(tmp_path / 'gone' / 'plot.png')
    with pytest.raises(OutputError) as refused:
        check_file_output(link, suffixes=('.png',))
    message = str(refused.value)
    assert message == (
        f'{link}: is a symbolic link to {tmp_path / "gone" / "plot.png"}, which does not exist '
        '(a dangling link); remove the link or choose another --plot'
    )
    assert not (tmp_path / 'gone').exists()  # nothing created through it
    # From the command line: the same words, before the bag is read, no traceback.
    status = main(['inspect', str(tmp_path / 'no_bag'), '--plot', str(link)])
    said = capsys.readouterr().err
    assert status == 2
    assert '(a dangling link); remove the link or choose another --plot' in said
    assert 'folder' not in said
    assert 'Traceback' not in said


def test_a_relative_dangling_link_names_where_it_points(tmp_path: Path) -> None:
    link = tmp_path / 'out'
    link.symlink_to('../moved/run')  # relative: resolved from the link's folder
    with pytest.raises(OutputError) as refused:
        check_target(link)
    assert str(refused.value) == (
        f'{link}: is a symbolic link to ../moved/run ({tmp_path.parent / "moved" / "run"}), '
        'which does not exist (a dangling link); create that folder, remove the link or choose '
        'another --out'
    )
