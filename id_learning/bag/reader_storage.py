"""What a bag's storage files say against its metadata.yaml: types, encodings, file order.

Kept apart from ``reader.py`` (which opens bags and reads messages): these checks look at the
storage plugins rosbags opened, one per file listed in metadata.yaml.

- A topic whose type in metadata.yaml is not its storage channel's type reads as empty (rosbags
  matches messages by topic and type): refused, naming both types.
- A storage channel whose ``message_encoding`` is not ``cdr`` (a ROS 1 recording put into an
  MCAP file, ``ros1``) reads as empty too: refused, naming the topic, the encoding and the file.
- Files are read one after the other in the order metadata.yaml lists them. A list that
  contradicts the files' times (``base_1.mcap`` before ``base_0.mcap``) would make every reader
  see time run backwards at the seam: the files are read in the order of their first message
  times instead, and a note names the listed and the time order (``order_by_time``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from id_learning.bag.metadata_file import load_metadata
from id_learning.errors import BagError

__all__ = [
    'ROS2_ENCODING',
    'check_encodings',
    'check_storage_types',
    'listed_files',
    'order_by_time',
    'storage_types',
]

#: The one message encoding rosbag2 (ROS 2) bags hold.
ROS2_ENCODING = 'cdr'


def listed_files(path: Path) -> list[str]:
    """The storage files metadata.yaml lists (``relative_file_paths``); [] when unreadable."""
    try:
        meta = load_metadata(path)
        return [str(p) for p in meta['rosbag2_bagfile_information']['relative_file_paths']]
    except (BagError, yaml.YAMLError, KeyError, TypeError):
        return []


def _storages(reader: Any) -> list[Any]:
    """The per-file storage readers of an open rosbags Reader ([] when it does not expose them)."""
    storage = getattr(reader, 'storage', None)
    found = getattr(storage, 'storages', None)
    return found if isinstance(found, list) else []


def storage_types(reader: Any) -> dict[str, set[str]]:
    """Message types per topic as the storage files (not metadata.yaml) declare them.

    Empty when the rosbags version at hand does not expose its storage readers.
    """
    out: dict[str, set[str]] = {}
    for store in _storages(reader):
        for conn in getattr(store, 'connections', ()) or ():
            out.setdefault(str(conn.topic), set()).add(str(conn.msgtype))
    return out


def check_storage_types(path: Path, reader: Any, topics: Sequence[str]) -> None:
    """Refuse a topic whose type in metadata.yaml is not the type its storage channel holds.

    rosbags matches messages by topic and type, so such a topic would read as empty.

    Raises:
        BagError: names the topic, both types and the storage files.
    """
    stored = storage_types(reader)
    if not stored:
        return
    for topic in topics:
        in_storage = stored.get(topic, set())
        for msgtype in {c.msgtype for c in reader.connections if c.topic == topic} - in_storage:
            if not in_storage:
                continue
            raise BagError(
                f'{path}: topic {topic} has type {msgtype} in metadata.yaml but '
                f'{", ".join(sorted(in_storage))} in {", ".join(listed_files(path)) or "storage"}'
                '; the metadata and the storage disagree: fix metadata.yaml'
            )


def check_encodings(path: Path, reader: Any, topics: Sequence[str]) -> None:
    """Refuse a topic stored in a message encoding other than ``cdr``.

    rosbags pairs storage channels with metadata.yaml's topics by their encoding too, so such a
    topic would read as holding no messages, which names neither the encoding nor the cause.

    Raises:
        BagError: names the topic, the encoding found, the file and its message count.
    """
    for store in _storages(reader):
        for conn in getattr(store, 'connections', ()) or ():
            encoding = getattr(getattr(conn, 'ext', None), 'serialization_format', ROS2_ENCODING)
            if conn.topic not in topics or encoding == ROS2_ENCODING:
                continue
            raise BagError(
                f'{path}: topic {conn.topic} is stored with message_encoding {encoding!r} in '
                f'{Path(str(store.path)).name} ({int(conn.msgcount)} messages); rosbag2 (ROS 2) '
                f'bags hold {ROS2_ENCODING!r}: none of them can be read (a ROS 1 recording? '
                'convert it with rosbags-convert)'
            )


#: How far a storage file's first message may lie before the previous file's last [ns] (a
#: writer's reordering across a split; at most half the previous file's span): more is an
#: overlap of two recordings or copies.
OVERLAP_TOLERANCE_NS = 1_000_000_000


def _span(start: int, end: object) -> str:
    """A file's log-time span, for messages: '<start> to <end> ns since epoch'."""
    return f'{start} to {end} ns since epoch'


def order_by_time(path: Path, reader: Any) -> str | None:
    """Put an open reader's storage files in the order of their first message times.

    Returns:
        A note naming the listed and the time order when metadata.yaml lists the files in
        another order (the files are then read in time order), else None. Files without
        messages keep their place after those with messages.

    Raises:
        BagError: two files overlap in log time (a copy listed twice, two recordings in one).
    """
    stores = _storages(reader)
    found = [getattr(getattr(s, 'metadata', None), 'start_time', None) for s in stores]
    counts = [getattr(getattr(s, 'metadata', None), 'message_count', 0) for s in stores]
    starts = [start for start in found if isinstance(start, int)]
    if len(stores) < 2 or len(starts) != len(stores):
        return None
    timed = [k for k in range(len(stores)) if counts[k]]
    order = sorted(timed, key=lambda k: starts[k]) + [
        k for k in range(len(stores)) if k not in timed
    ]
    names = [Path(str(s.path)).name for s in stores]
    ends = [getattr(getattr(s, 'metadata', None), 'end_time', None) for s in stores]
    for first, then in itertools.pairwise(k for k in order if k in timed):
        end = ends[first]
        tolerance = (
            min(OVERLAP_TOLERANCE_NS, (end - starts[first]) // 2) if isinstance(end, int) else 0
        )
        if isinstance(end, int) and starts[then] < end - tolerance:
            raise BagError(
                f'{path}: its storage files {names[first]} and {names[then]} overlap in log time '
                f"({_span(starts[first], end)} and {_span(starts[then], ends[then])}): a bag's "
                'files follow each other in time; is one a copy of the other, or are two '
                'recordings in one folder? Keep one, or import them as two bags'
            )
    if order == list(range(len(stores))):
        return None
    stores[:] = [stores[k] for k in order]
    return (
        f'{path}: metadata.yaml lists the storage files as {", ".join(names)}, but their '
        f'messages begin in the order {", ".join(names[k] for k in order)}: read in that order '
        '(fix relative_file_paths in metadata.yaml)'
    )
