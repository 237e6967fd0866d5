"""Read rosbag2 bags (MCAP or SQLite storage) through rosbags; errors name file and topic."""

from __future__ import annotations

import logging
import os
import struct
import traceback
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import Any

import numpy as np
import yaml
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError
from tqdm import tqdm

from id_learning.bag.messages import (
    JOINT_STATE,
    JointStateSeries,
    clock_step,
    decode_joint_state,
    typestore,
)
from id_learning.bag.metadata_file import (
    METADATA_FILE,
    RECOVER_HINT,
    STORAGE_SUFFIXES,
    bag_path_problem,
    load_metadata,
    metadata_text,
    missing_key,
    refuse_special_files,
    storage_mismatch,
)
from id_learning.bag.reader_paths import BagReader, folder_is_no_bag, storage_files
from id_learning.bag.reader_storage import check_encodings, check_storage_types, order_by_time
from id_learning.bag.reader_storage import listed_files as _listed_files
from id_learning.errors import BagError, DatasetError
from id_learning.output_kinds import writer_of

__all__ = [
    'BagInfo',
    'JointStateSeries',
    'TopicInfo',
    'bag_custom_data',
    'bag_info',
    'iter_messages',
    'iter_raw',
    'iter_typed',
    'read_joint_states',
]

_LOG = logging.getLogger(__name__)
#: ``staged_bag.STAGING_SUFFIX`` (that module imports this package: not imported here).
_STAGING_SUFFIX = '.writing'
#: Bags whose unlisted storage files were already warned about (one warning per bag).
_WARNED_UNLISTED: set[tuple[Path, tuple[str, ...]]] = set()
#: Notes on misordered storage files already warned about (one warning per bag).
_WARNED_ORDER: set[str] = set()


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class BagInfo:
    """What a bag's metadata says."""

    path: Path
    storage: str
    files: tuple[str, ...]
    start_ns: int
    duration_ns: int
    topics: tuple[TopicInfo, ...]
    custom_data: dict[str, str] = field(default_factory=dict)
    #: metadata.yaml lists the storage files against their times (``order_by_time``'s note).
    order_note: str | None = None

    def topic(self, name: str) -> TopicInfo:
        """Return a topic by name.

        Raises:
            BagError: the bag has no such topic (lists those it has), or holds it with several
                message types (names each).
        """
        _refuse_several_types(
            self.path, [(t.name, t.msgtype, t.count) for t in self.topics], [name]
        )
        for topic in self.topics:
            if topic.name == name:
                return topic
        raise BagError(
            f'{self.path}: missing topic {name}; the bag has {[t.name for t in self.topics]}'
        )


def _open(path: Path) -> tuple[Reader, str | None]:
    """Open a bag, its storage files in time order; (reader, note on their order or None)."""
    if (why := bag_path_problem(path)) is not None:
        raise BagError(why)  # a device, a FIFO: said so, never read, no recover hint
    if not path.exists():
        # ``staged_bag`` writes a bag beside its place, in ``.<name>.writing``, until complete.
        staging = path.parent / f'.{path.name}{_STAGING_SUFFIX}'
        raise BagError(
            f'{path}: no such bag; it is being written in {staging} (by a command still running, '
            'or left by one that was killed: its next writer removes it)'
            if staging.is_dir()
            else f'{path}: no such bag'
        )
    if path.is_file():
        within = (
            f'; it is a file of the bag {path.parent}: give that folder'
            if (path.parent / METADATA_FILE).is_file()
            else ''
        )
        raise BagError(
            f'{path}: expected a rosbag2 folder (with metadata.yaml), got a file{within}'
        )
    if not (path / METADATA_FILE).exists():
        if (why := folder_is_no_bag(path)) is not None:
            raise BagError(f'{path}: {why}')
        if (pid := writer_of(path)) is not None:
            raise BagError(
                f'{path}: being written by process {pid} (it holds {path.name}.lock): its '
                'metadata.yaml comes when that process ends; read the bag then'
            )
        raise BagError(f'{path}: not a complete rosbag2 folder (no metadata.yaml); {RECOVER_HINT}')
    _check_metadata(path)
    reader = BagReader(path)
    try:
        _open_reader(path, reader)
    except BaseException:
        reader.drop_view()
        raise
    _warn_unlisted(path, reader)
    note = order_by_time(path, reader)
    if note is not None and note not in _WARNED_ORDER:
        _WARNED_ORDER.add(note)
        _LOG.warning('%s', note)
    return reader, note


def _open_reader(path: Path, reader: Reader) -> None:
    """Open ``reader`` on bag ``path``; what fails is a BagError naming the bag and the cause."""
    try:
        reader.open()
    except (ReaderError, struct.error, EOFError, ValueError, OSError) as err:
        raise BagError(f'{path}: cannot open bag: {err}; {RECOVER_HINT}') from err
    except Exception as err:
        files = ', '.join(_listed_files(path)) or 'the storage files'
        if not _is_decode_error(err):
            if (torn := _storage_failure(err)) is None:
                raise
            raise BagError(
                f'{path}: cannot open bag: {torn or files} is torn or corrupt (its storage '
                f'reader failed: {type(err).__name__}: {err}); {RECOVER_HINT}'
            ) from err
        raise BagError(
            f'{path}: cannot open bag: {files} do(es) not decompress or decode '
            f'({type(err).__name__}: {err}){_compression_note(path)}'
        ) from err


def _check_metadata(path: Path) -> None:
    """Refuse a metadata.yaml that is no file or not text, or lists storage files outside the bag.

    metadata.yaml is read under its cap (``metadata_file``); it and the storage files must be
    regular files (a FIFO would block rosbags' read forever, a device never end). rosbags reads
    each listed file by its name from the bag folder, so an absolute entry or one leading out of
    it (``../other/other_0.mcap``) names data the bag does not hold.

    Raises:
        BagError: names metadata.yaml and why (a key rosbags needs missing, a storage the files
            are not), a storage file and what it is, or the bag, the entry and why.
    """
    refuse_special_files(path)  # metadata.yaml first: named as what it is, before a read
    text = metadata_text(path)
    info = _check_metadata_shape(path / METADATA_FILE, text)
    listed = _listed_files(path)  # [] when unreadable: rosbags names what is wrong
    for entry in listed:
        why = 'an absolute path' if PurePath(entry).is_absolute() else 'outside the bag folder'
        if PurePath(entry).is_absolute() or os.path.normpath(entry).split(os.sep)[0] == os.pardir:
            raise BagError(
                f'{path}: metadata.yaml relative_file_paths lists {entry!r}, {why}; a bag holds '
                f'its storage files in its own folder: copy the file in and list it by name '
                f'({PurePath(entry).name!r})'
            )
    refuse_special_files(path, listed)  # those in subfolders too
    if info is not None and (
        wrong := missing_key(path, info, text) or storage_mismatch(path, info)
    ):
        raise BagError(wrong)


def _check_metadata_shape(file: Path, text: str) -> dict[str, Any] | None:
    """Refuse a metadata.yaml that is empty or not a mapping holding rosbag2_bagfile_information.

    Text that is not YAML is left to rosbags, which names the line (None is returned).

    Raises:
        BagError: names the file, what it holds instead, and the recover hint.
    """
    try:
        meta = yaml.safe_load(text)
    except yaml.YAMLError:
        return None
    if meta is None:
        what = 'is empty' if not text.strip() else 'holds no YAML value (only comments)'
    elif not isinstance(meta, dict):
        what = f'holds a {type(meta).__name__}, not a mapping'
    elif not isinstance(info := meta.get('rosbag2_bagfile_information'), dict):
        what = 'has no rosbag2_bagfile_information mapping'
    else:
        return info
    raise BagError(f'{file} {what}; {RECOVER_HINT}')


def _storage_failure(err: BaseException) -> str | None:
    """The storage file's name ('' when unknown) if ``err`` was raised in a rosbags storage plugin.

    Judged by the traceback's frames (which module raised), not by the message: anything raised
    there reading a file means the file is torn or corrupt (a bare MCAP magic makes ``ord``
    raise TypeError, a damaged length field MemoryError or OverflowError, a bad offset OSError).
    """
    found: str | None = None
    for frame, _ in traceback.walk_tb(err.__traceback__):
        if str(frame.f_globals.get('__name__')).startswith('rosbags.rosbag2.storage_'):
            local = frame.f_locals
            name = getattr(local.get('self'), 'path', None) or getattr(local.get('bio'), 'name', 0)
            found = Path(name).name if isinstance(name, (str, os.PathLike)) else found or ''
    return found


#: Top-level modules whose exceptions mean a storage file does not decompress or decode.
_DECODE_MODULES = frozenset(
    {'zstd', 'zstandard', 'compression', 'backports', 'lz4', 'mcap', 'sqlite3', 'rosbags'}
)


def _is_decode_error(err: BaseException) -> bool:
    """Whether ``err`` comes from a decompressor, a storage plugin or a decoder."""
    module = type(err).__module__.split('.')[0]
    return module in _DECODE_MODULES or isinstance(err, (KeyError, IndexError, UnicodeError))


def _compression_note(path: Path) -> str:
    """'; metadata.yaml claims ...' when it names a compression, else ''."""
    try:
        info = load_metadata(path)['rosbag2_bagfile_information']
        fmt, mode = info.get('compression_format') or '', info.get('compression_mode') or ''
    except (BagError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return ''
    if not fmt:
        return ''
    return (
        f'; metadata.yaml claims compression_format {fmt}, compression_mode {mode or "none"}: '
        'the files do not match that claim, fix metadata.yaml or the files'
    )


def _warn_unlisted(path: Path, reader: Reader) -> None:
    """Warn once per bag about storage files in its folder that metadata.yaml does not list.

    rosbags reads only the listed files: an extra ``bag_1.mcap`` (a second recording copied in,
    a split the metadata lost) is silently left out of the data, which the user should know.
    """
    listed = {Path(name).name for name in getattr(reader, 'paths', ())} or {
        Path(str(item)).name for item in _listed_files(path)
    }
    extra = tuple(sorted({p.name for p in data_files(path)} - listed))
    key = (path.resolve(), extra)
    if extra and key not in _WARNED_UNLISTED:
        _WARNED_UNLISTED.add(key)
        _LOG.warning(
            '%s: %s not listed in metadata.yaml and not read (listed: %s); move it out or '
            'record it as a bag of its own',
            path,
            ', '.join(extra),
            ', '.join(sorted(listed)) or 'none',
        )


def data_files(path: Path) -> list[Path]:
    """A log file itself, or a bag folder's storage files (``.mcap``, ``.db3``).

    metadata.yaml is left out: an edited copy of it must not hide a duplicate recording. Files
    the twin writes beside a bag (ground truth, its config copy) are no part of the data either.
    """
    if path.is_file():
        return [path]
    if not path.is_dir():
        return []  # a device, a FIFO: no data files (the readers name what it is)
    return sorted(p for p in path.iterdir() if p.is_file() and p.suffix in STORAGE_SUFFIXES)


def bag_info(path: Path | str) -> BagInfo:
    """Read a bag's topics, counts and time span.

    Raises:
        BagError: the folder is missing, incomplete, truncated or corrupt.
    """
    path = Path(path)
    reader, note = _open(path)
    files = storage_files(path)
    try:
        topics = tuple(TopicInfo(c.topic, c.msgtype, int(c.msgcount)) for c in reader.connections)
        return BagInfo(
            path=path,
            storage='mcap' if all(n.endswith(('.mcap', '.mcap.zstd')) for n in files) else 'other',
            files=files,
            start_ns=int(reader.start_time) if reader.message_count else 0,
            # rosbags' end_time is one past the latest message; report last minus first.
            duration_ns=int(reader.end_time - 1 - reader.start_time)
            if reader.message_count
            else 0,
            topics=topics,
            custom_data=bag_custom_data(path),
            order_note=note,
        )
    finally:
        reader.close()


def bag_custom_data(path: Path | str) -> dict[str, str]:
    """``custom_data`` of a bag's ``metadata.yaml`` (rosbag2 keeps string entries there).

    Read from the file alone, without opening the bag's storage.

    Raises:
        BagError: metadata.yaml is missing, no regular file, over its cap, or not YAML.
    """
    path = Path(path)
    try:
        info = load_metadata(path).get('rosbag2_bagfile_information', {})
    except (yaml.YAMLError, AttributeError) as err:  # BagError names the file itself
        raise BagError(f'{path}: cannot read metadata.yaml: {err}') from err
    custom = info.get('custom_data') if isinstance(info, dict) else None
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def _refuse_several_types(
    path: Path, found: Sequence[tuple[str, str, int]], topics: Sequence[str]
) -> None:
    """Refuse the first of ``topics`` that ``found`` (topic, type, count) gives several types.

    A topic carries one type: selected by topic, one type would be read and the rest called
    missing or empty.

    Raises:
        BagError: names the topic and each type with its message count.
    """
    for topic in topics:
        types: dict[str, int] = {}
        for name, msgtype, count in found:
            if name == topic:
                types[msgtype] = types.get(msgtype, 0) + int(count)
        if len(types) > 1:
            held = ', '.join(f'{t} ({n} message{"s" * (n != 1)})' for t, n in types.items())
            raise BagError(
                f'{path}: topic {topic} holds {len(types)} message types: {held}; a topic '
                'carries one type: record the others on topics of their own'
            )


def iter_raw(path: Path | str, topics: Sequence[str]) -> Iterator[tuple[str, int, bytes]]:
    """Yield (topic, log time [ns], serialized bytes) of the given topics in log-time order.

    Raises:
        BagError: a topic is missing or holds messages of several types, or the file is
            truncated or corrupt.
    """
    for topic, _, log_ns, data in iter_typed(path, topics, several_types=False):
        yield topic, log_ns, data


def iter_typed(
    path: Path | str, topics: Sequence[str], *, several_types: bool = True
) -> Iterator[tuple[str, str, int, bytes]]:
    """Yield (topic, message type, log time [ns], serialized bytes) in log-time order.

    A topic holding messages of several types is read whole, each message with its type (for
    reporting on such a bag); ``several_types=False`` refuses it, as ``iter_raw`` does.

    Raises:
        BagError: a topic is missing, or the file is truncated or corrupt.
    """
    path = Path(path)
    reader, _ = _open(path)
    try:
        connections = [conn for conn in reader.connections if conn.topic in topics]
        present = {conn.topic for conn in reader.connections}
        missing = [topic for topic in topics if topic not in present]
        if missing:
            raise BagError(f'{path}: missing topic(s) {missing}; the bag has {sorted(present)}')
        if not several_types:
            found = [(c.topic, c.msgtype, int(c.msgcount)) for c in connections]
            _refuse_several_types(path, found, topics)
        check_storage_types(path, reader, topics)
        check_encodings(path, reader, topics)
        held = dict.fromkeys(topics, 0)
        try:
            for conn, timestamp, data in reader.messages(connections=connections):
                held[conn.topic] += 1
                yield conn.topic, conn.msgtype, int(timestamp), bytes(data)
        except (ReaderError, struct.error, EOFError, ValueError, KeyError) as err:
            raise BagError(
                f'{path}: corrupt or truncated bag while reading {topics}: {err}; {RECOVER_HINT}'
            ) from err
        except Exception as err:  # zstd/lz4 raise their own error types on damaged chunks
            torn = _storage_failure(err)
            if not _is_decode_error(err) and torn is None:
                raise
            raise BagError(
                f'{path}: damaged or undecodable storage data{f" in {torn}" if torn else ""} '
                f'while reading {list(topics)} ({type(err).__name__}: {err})'
                f'{_compression_note(path)}; {RECOVER_HINT}'
            ) from err
        stated = {t: sum(int(c.msgcount) for c in connections if c.topic == t) for t in topics}
        _warn_miscounted(path, stated, held)
    finally:
        reader.close()


def _warn_miscounted(path: Path, stated: Mapping[str, int], held: Mapping[str, int]) -> None:
    """Warn when metadata.yaml's message counts are not what the storage files held.

    The messages read are the data; a count that disagrees means metadata.yaml was edited or
    copied from another recording, which the user should know before trusting either.
    """
    wrong = [f'{t} {stated[t]} stated, {held[t]} held' for t in stated if stated[t] != held[t]]
    if wrong:
        _LOG.warning(
            '%s: metadata.yaml message counts disagree with the storage files (%s); the '
            'messages the files hold were read: fix or regenerate metadata.yaml '
            '(`id-learning inspect` lists every mismatch)',
            path,
            '; '.join(wrong),
        )


def iter_messages(path: Path | str, topic: str) -> Iterator[tuple[int, Any]]:
    """Yield (log time [ns], message) of any ROS 2 Jazzy message type on a topic, in log order.

    Messages are decoded strictly: bytes beyond the message's size are an error, as in rosbags.

    Raises:
        BagError: missing topic, a type rosbags does not know, a message that does not decode
            (named by index and log time), corrupt file.
    """
    path = Path(path)
    msgtype = bag_info(path).topic(topic).msgtype
    store = typestore()
    if msgtype not in store.types:
        raise BagError(f'{path}: topic {topic} has type {msgtype}, unknown to ROS 2 Jazzy')
    for index, (_, log_ns, data) in enumerate(iter_raw(path, [topic])):
        try:
            message = store.deserialize_cdr(data, msgtype)
        except Exception as err:  # rosbags raises SerdeError, struct and index errors alike
            raise BagError(
                f'{path}: {topic} message {index} (log time {log_ns} ns) is not a valid '
                f'{msgtype}: {err}'
            ) from err
        yield log_ns, message


def _check_stored_type(path: Path, topic: str) -> None:
    """Refuse, naming both types, a topic whose storage holds another type than metadata.yaml.

    Raises:
        BagError: ``reader_storage.check_storage_types``'s message (fix metadata.yaml).
    """
    reader, _ = _open(path)
    try:
        check_storage_types(path, reader, [topic])
    finally:
        reader.close()


def read_joint_states(
    path: Path | str,
    topic: str,
    *,
    progress: bool = False,
    fields: tuple[str, ...] = ('position', 'velocity', 'effort'),
) -> JointStateSeries:
    """Read and stack every sensor_msgs/JointState on a topic.

    ``fields``: the arrays read (and checked); the others come back None, whatever they hold
    (the motor currents' topic carries its values in effort alone). The samples come in
    log-time order, unless the recorder's clock stepped back while recording (``clock_step``):
    then in header-stamp order, with a warning naming the topic, the sample and the step.

    Raises:
        BagError: missing topic, wrong message type, corrupt file.
        DatasetError: messages disagree on joint names or array lengths, or a header stamp is
            no time (``header_stamp_problem``); names the sample.
    """
    path = Path(path)
    info = bag_info(path)
    msgtype = info.topic(topic).msgtype
    if msgtype != JOINT_STATE:
        _check_stored_type(path, topic)  # metadata.yaml may be what is wrong, not the data
        raise BagError(f'{path}: topic {topic} has type {msgtype}, expected {JOINT_STATE}')
    stamps: list[int] = []
    logs: list[int] = []
    wanted: dict[str, list[np.ndarray]] = {key: [] for key in fields}
    names: tuple[str, ...] | None = None
    lengths: dict[str, int] = {}
    messages = tqdm(
        iter_raw(path, [topic]),
        total=info.topic(topic).count,
        unit='msg',
        desc=f'reading {topic}',
        disable=not progress,
        leave=False,
    )
    for index, (_, log_ns, data) in enumerate(messages):
        try:
            msg = decode_joint_state(data)
        except Exception as err:  # rosbags raises SerdeError, struct and index errors alike
            raise BagError(
                f'{path}: {topic} message {index} (log time {log_ns} ns) is not a valid '
                f'{JOINT_STATE}: {err}'
            ) from err
        if msg.stamp_problem is not None:
            raise DatasetError(
                f'{path}: {topic} sample {index} (log time {log_ns} ns): invalid header stamp: '
                f'{msg.stamp_problem}; a stamp that is no time cannot be placed (the replay and '
                "the predictor refuse it too): fix the recorder's or the converter's stamps"
            )
        if names is None:
            names = msg.name
            lengths = {key: len(getattr(msg, key)) for key in wanted}
            for key, length in lengths.items():
                if length not in (0, len(names)):
                    raise DatasetError(
                        f'{path}: {topic} sample 0: {key} has {length} values '
                        f'for {len(names)} joints'
                    )
        elif msg.name != names:
            raise DatasetError(
                f'{path}: {topic} sample {index} (stamp {msg.stamp_ns} ns): '
                f'joint names {list(msg.name)} '
                f"differ from the first message's {list(names)}"
            )
        for key, values in wanted.items():
            array = getattr(msg, key)
            if len(array) != lengths[key]:
                raise DatasetError(
                    f'{path}: {topic} sample {index} (stamp {msg.stamp_ns} ns): {key} has '
                    f'{len(array)} values, earlier samples have {lengths[key]}'
                )
            if lengths[key]:
                values.append(array)
        stamps.append(msg.stamp_ns)
        logs.append(log_ns)
    if names is None:
        raise DatasetError(f'{path}: topic {topic} has no messages')
    step = clock_step(np.array(stamps, dtype=np.int64), np.array(logs, dtype=np.int64))
    order = np.arange(len(stamps)) if step is None else step.order
    if step is not None:
        _LOG.warning('%s: %s; read in header-stamp order', path, step.describe(topic))

    def stacked(key: str) -> np.ndarray | None:
        return np.vstack(wanted[key])[order] if lengths.get(key) else None

    return JointStateSeries(
        topic=topic,
        stamps_ns=np.array(stamps, dtype=np.int64)[order],
        log_ns=np.array(logs, dtype=np.int64)[order],
        names=names,
        position=stacked('position'),
        velocity=stacked('velocity'),
        effort=stacked('effort'),
    )
