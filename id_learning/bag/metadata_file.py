"""A bag folder's own files: metadata.yaml read whole under a cap, the storage files kept files.

What a recorder writes into a bag folder are regular files: ``metadata.yaml`` and the storage
files (``.mcap``, ``.db3``). A FIFO, a device or a socket in their place (a link to
``/dev/zero``, a pipe nobody writes) would make a read block forever or never end; each is
refused at once, naming the file and what it is, and nothing there suggests ``bag recover``
(which refuses them too). A bag path that is itself no folder is named for what it is.

metadata.yaml is read whole, through ``config_io.read_capped``, at most
``MAX_BAG_METADATA_BYTES``: parsing it is slow (PyYAML, rosbags' ruamel: about 0.4 s per MiB,
and a bag is opened several times per command), and no recording's metadata comes near the cap.
The storage files are read as streams (rosbags, the recovery's scan): only their kind is checked.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path, PurePath
from typing import Any

import yaml

from id_learning.config_io import read_capped, special_kind
from id_learning.errors import BagError

__all__ = [
    'MAX_BAG_METADATA_BYTES',
    'METADATA_FILE',
    'RECOVER_HINT',
    'STORAGE_SUFFIXES',
    'bag_path_problem',
    'load_metadata',
    'metadata_text',
    'refuse_special_files',
]

METADATA_FILE = 'metadata.yaml'
#: The suffixes of the storage files a bag folder holds.
STORAGE_SUFFIXES = ('.mcap', '.db3')
#: The largest metadata.yaml read [bytes]. rosbag2 writes about 0.6 KiB per topic (QoS profiles
#: and type hash included) and 0.2 KiB per storage file: 4 MiB holds a thousand topics split
#: over ten thousand files. The twin's bags hold 1 KiB.
MAX_BAG_METADATA_BYTES = 4 * 2**20

RECOVER_HINT = 'if the recording was interrupted, `id-learning bag recover PATH` rebuilds it'

#: What the messages call a bag's metadata.yaml (``read_capped``'s ``what``).
_WHAT = 'bag metadata'
#: What a bag path that is no folder is, for the kinds that are neither file nor folder.
_NOT_A_FOLDER = (
    'not a bag folder: a rosbag2 bag is a folder holding metadata.yaml and its storage files '
    '(.mcap); pass that folder'
)


def bag_path_problem(path: Path) -> str | None:
    """Why ``path`` cannot be a bag folder for what it is (a device, a FIFO, a socket), or None.

    None for a folder, a regular file and a missing path: the callers word those themselves.
    """
    kind = special_kind(path)
    if kind is None or kind == 'a folder':
        return None
    return f'{path}: {kind}, {_NOT_A_FOLDER}'


def metadata_text(path: Path) -> str:
    """The text of bag folder ``path``'s metadata.yaml: a regular UTF-8 file, capped in size.

    Raises:
        BagError: the file is missing or unreadable, no regular file (names its kind), larger
            than ``MAX_BAG_METADATA_BYTES`` or not UTF-8; names the file.
    """
    file = Path(path) / METADATA_FILE
    data = read_capped(file, _WHAT, MAX_BAG_METADATA_BYTES, regular=True, error=BagError)
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise BagError(
            f'{file}: not a text YAML file (byte {err.start} is not UTF-8: binary or damaged); '
            f'{RECOVER_HINT}'
        ) from err


def load_metadata(path: Path) -> Any:
    """Bag folder ``path``'s metadata.yaml parsed (``metadata_text``, then safe YAML).

    Raises:
        BagError: ``metadata_text``'s reasons.
        yaml.YAMLError: the text is no YAML (callers that report it name the line).
    """
    return yaml.safe_load(metadata_text(path))


def refuse_special_files(path: Path, listed: Iterable[str] = ()) -> None:
    """Refuse a bag's metadata.yaml or storage file that exists but is no regular file.

    Checked: metadata.yaml, the storage files in the folder (by suffix) and the entries
    metadata.yaml lists (``listed``, relative to the folder). A missing file passes (the
    callers name it); a link passes when its target is a regular file.

    Raises:
        BagError: names the first such file and what it is (a FIFO, a device, a socket).
    """
    try:
        names = sorted(p.name for p in path.iterdir() if p.name.endswith(STORAGE_SUFFIXES))
    except OSError:
        names = []  # the folder itself is judged by the callers
    files = [path / METADATA_FILE, *(path / name for name in names)]
    files += [path / PurePath(entry) for entry in listed]
    for file in dict.fromkeys(files):
        # A folder in a file's place fails at once, naming itself; these would block or not end.
        if (kind := special_kind(file)) not in (None, 'a folder'):
            raise BagError(
                f'{file}: {kind}, not a regular file; a bag folder holds its metadata.yaml and '
                'storage files as files: put the recorded file there, or pass its own bag'
            )
