"""A bag folder's own files: metadata.yaml read whole under a cap, the storage files kept files.

What a recorder writes into a bag folder are regular files: ``metadata.yaml`` and the storage
files (``.mcap``, ``.db3``). A FIFO, a device or a socket in their place (a link to
``/dev/zero``, a pipe nobody writes) would make a read block forever or never end; each is
refused at once, naming the file and what it is, and nothing there suggests ``bag recover``
(which refuses them too). A bag path that is itself no folder is named for what it is.

metadata.yaml is read whole, through ``config_io.read_capped``, at most
``MAX_BAG_METADATA_BYTES``: parsing it is slow (PyYAML, rosbags' ruamel: about 0.4 s per MiB,
and a bag is opened several times per command), and no recording's metadata comes near the cap.
The storage files are read as streams (rosbags, the recovery's scan): only their kind is checked,
and their first bytes against the storage metadata.yaml names (``storage_mismatch``).

A metadata.yaml cut short or edited may lack a key rosbags needs (``missing_key``): named by its
path in the file, with ``bag recover``, which rebuilds metadata.yaml from the storage files.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
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
    'missing_key',
    'refuse_special_files',
    'storage_mismatch',
]

METADATA_FILE = 'metadata.yaml'
#: The suffixes of the storage files a bag folder holds.
STORAGE_SUFFIXES = ('.mcap', '.db3')
#: The largest metadata.yaml read [bytes]. rosbag2 writes about 0.6 KiB per topic (QoS profiles
#: and type hash included) and 0.2 KiB per storage file: 4 MiB holds a thousand topics split
#: over ten thousand files. The twin's bags hold 1 KiB.
MAX_BAG_METADATA_BYTES = 4 * 2**20

RECOVER_HINT = 'if the recording was interrupted, `id-learning bag recover PATH` rebuilds it'

#: The section of metadata.yaml that holds what rosbag2 knows of the bag.
_INFO = 'rosbag2_bagfile_information'
#: The keys rosbags needs in that section, with those it needs inside them.
_REQUIRED: dict[str, tuple[str, ...]] = {
    'version': (),
    'storage_identifier': (),
    'relative_file_paths': (),
    'duration': ('nanoseconds',),
    'starting_time': ('nanoseconds_since_epoch',),
    'message_count': (),
    'topics_with_message_count': (),
}
#: The keys rosbags needs in each topic's ``topic_metadata``.
_TOPIC_KEYS = ('name', 'type', 'serialization_format')
#: What each storage rosbag2 names holds in its first bytes, and what to call such a file.
_MAGIC = {'mcap': b'\x89MCAP0\r\n', 'sqlite3': b'SQLite format 3\x00'}
_KIND = {'mcap': 'an MCAP file', 'sqlite3': 'an SQLite database'}

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


def _missing_in_topics(topics: object) -> str | None:
    """The first key a ``topics_with_message_count`` list lacks, as its path, or None."""
    if not isinstance(topics, list):
        return f'{_INFO}.topics_with_message_count (a list)'
    for index, entry in enumerate(topics):
        where = f'{_INFO}.topics_with_message_count[{index}]'
        meta = entry.get('topic_metadata') if isinstance(entry, dict) else None
        if not isinstance(meta, dict):
            return f'{where}.topic_metadata'
        name = f' (topic {meta["name"]!r})' if 'name' in meta else ''
        for key in _TOPIC_KEYS:
            if key not in meta:
                return f'{where}.topic_metadata.{key}{name}'
        if 'message_count' not in entry:
            return f'{where}.message_count{name}'
    return None


def _first_missing(info: Mapping[str, Any]) -> str | None:
    """The first key (or value) rosbags needs that ``info`` lacks, as its path, or None."""
    for key, inner in _REQUIRED.items():
        value = info.get(key)
        if value is None:
            return f'{_INFO}.{key}'
        lacking = [k for k in inner if not isinstance(value, dict) or k not in value]
        if lacking:
            return f'{_INFO}.{key}.{lacking[0]}'
    if not isinstance(info['relative_file_paths'], list):
        return f'{_INFO}.relative_file_paths (a list)'
    return _missing_in_topics(info['topics_with_message_count'])


def missing_key(path: Path, info: Mapping[str, Any], text: str) -> str | None:
    """Why metadata.yaml lacks a key rosbags needs (its path in the file, the hint), or None.

    ``info`` is the parsed ``rosbag2_bagfile_information`` mapping and ``text`` the file's text.
    rosbags would say only ``A metadata key is missing KeyError('type')``.
    """
    found = _first_missing(info)
    if found is None:
        return None
    size = len(text.encode('utf-8'))
    cut = f'; it ends mid-line at byte {size}: cut short' if not text.endswith('\n') else ''
    return (
        f'{path / METADATA_FILE} is incomplete: it lacks {found}{cut}; `id-learning bag recover '
        f'{path}` rebuilds metadata.yaml from the storage files'
    )


def storage_mismatch(path: Path, info: Mapping[str, Any]) -> str | None:
    """Where metadata.yaml's ``storage_identifier`` is not what a listed file holds, or None.

    Judged by the file's magic bytes (MCAP, SQLite); rosbags would open an MCAP file as a
    database and say only that it is none.
    """
    named = info.get('storage_identifier')
    listed = info.get('relative_file_paths')
    for entry in listed if isinstance(listed, list) else ():
        file = path / PurePath(str(entry))
        try:
            with file.open('rb') as stream:
                head = stream.read(16)
        except OSError:
            continue  # a missing file is named by the reader
        kind = next((kind for kind, magic in _MAGIC.items() if head.startswith(magic)), None)
        if kind is None or kind == named:
            continue
        recover = (
            f', or run `id-learning bag recover {path}`, which rebuilds metadata.yaml from the '
            'files'
            if kind == 'mcap'
            else ''
        )
        return (
            f'{path / METADATA_FILE} names storage_identifier {named!r}, but {entry} is '
            f'{_KIND[kind]} (its first bytes are {_MAGIC[kind]!r}); set storage_identifier: '
            f'{kind} in metadata.yaml{recover}'
        )
    return None
