"""rosbag2 writer with MCAP storage: a folder with ``metadata.yaml`` and ``.mcap`` file(s).

Messages are stored as serialized CDR bytes, as they came (no re-serialization). MCAP chunks are
zstd-compressed; a small chunk size bounds what a crash can lose, since everything up to the last
finished chunk is on disk.

What reached the file: MCAP keeps a message in the chunk in progress until the chunk is full or
flushed. The file is written unbuffered (``os.write``), so once a chunk is handed over without
error its messages are in the file, and ``id-learning bag recover`` gives them back whatever
happens next. ``on_disk`` counts those messages per topic. A write that fails (disk full, a file
size limit) stops the writer for good: the messages of the chunk in progress are lost, nothing
more is appended after the torn chunk, and every further call raises ``BagError`` naming the bag
and the OS's reason.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Self, TypeVar

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from id_learning.bag.messages import message_definition
from id_learning.errors import BagError
from id_learning.outputs import bag_output, os_reason

__all__ = ['BagWriteError', 'BagWriter', 'write_metadata']

ROSBAG2_VERSION = 9
DEFAULT_CHUNK_BYTES = 1 << 20

_T = TypeVar('_T')


class BagWriteError(BagError):
    """The storage refused a write (a full disk, an I/O error): ``reason`` is the OS's words.

    The message says what the file keeps (a recorder's bag is recoverable); a writer that
    discards its bag (``staged_bag``) says so in its own words from ``reason``.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


class _DirectFile:
    """A file written with ``os.write``, no buffer: what ``write`` took is in the file.

    MCAP's writer wraps a raw stream in a ``BufferedWriter``; this is not one, so it takes it as
    the stream itself.
    """

    def __init__(self, path: Path) -> None:
        self.name = str(path)
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._position = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data).cast('B')
        while view:
            written = os.write(self._fd, view)
            self._position += written
            view = view[written:]
        return len(data)

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        """Nothing is buffered here."""

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


@dataclass
class _Topic:
    name: str
    msgtype: str
    type_hash: str
    channel_id: int
    count: int = 0


@dataclass
class _FileStats:
    path: str
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None


def write_metadata(
    bag_dir: Path,
    topics: list[tuple[str, str, str, int]],
    files: list[tuple[str, int, int, int]],
    custom_data: dict[str, str] | None = None,
) -> None:
    """Write a rosbag2 v9 ``metadata.yaml`` atomically.

    Args:
        bag_dir: the bag folder.
        topics: (name, msgtype, RIHS01 type hash, message count) per topic.
        files: (relative path, first log time [ns], last log time [ns], message count) per file.
        custom_data: string entries for rosbag2's ``custom_data`` beside ``writer``.
    """
    starts = [first for _, first, _, count in files if count]
    ends = [last for _, _, last, count in files if count]
    start = min(starts) if starts else 0
    end = max(ends) if ends else 0
    info = {
        'version': ROSBAG2_VERSION,
        'storage_identifier': 'mcap',
        'relative_file_paths': [path for path, *_ in files],
        'duration': {'nanoseconds': end - start},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': sum(count for *_, count in files),
        'topics_with_message_count': [
            {
                'topic_metadata': {
                    'name': name,
                    'type': msgtype,
                    'serialization_format': 'cdr',
                    'offered_qos_profiles': [],
                    'type_description_hash': type_hash,
                },
                'message_count': count,
            }
            for name, msgtype, type_hash, count in topics
        ],
        'compression_format': '',
        'compression_mode': '',
        'files': [
            {
                'path': path,
                'starting_time': {'nanoseconds_since_epoch': first if count else 0},
                'duration': {'nanoseconds': (last - first) if count else 0},
                'message_count': count,
            }
            for path, first, last, count in files
        ],
        'custom_data': {'writer': 'id_learning', **(custom_data or {})},
        'ros_distro': 'jazzy',
    }
    text = yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False)
    tmp = bag_dir / 'metadata.yaml.tmp'
    try:
        tmp.write_text(text, encoding='utf-8')
        tmp.replace(bag_dir / 'metadata.yaml')
    finally:  # a torn tmp would make the folder foreign, no longer a bag to recover
        tmp.unlink(missing_ok=True)


class BagWriter:
    """Write serialized messages to a rosbag2 MCAP bag folder.

    Use as a context manager; ``metadata.yaml`` is written on close. Optional splitting starts a
    new ``.mcap`` file once the current one spans ``split_duration_ns`` or holds ``split_bytes``.
    From ``open`` to ``close`` it holds ``<path>.lock`` (``outputs.bag_output``): a second writer
    of the same bag is refused, naming this one's pid.
    """

    def __init__(
        self,
        path: Path | str,
        *,
        overwrite: bool = False,
        chunk_bytes: int = DEFAULT_CHUNK_BYTES,
        split_duration_ns: int | None = None,
        split_bytes: int | None = None,
        custom_data: dict[str, str] | None = None,
        flag: str = '--force',
    ) -> None:
        """Prepare a bag folder; nothing is written before ``open()``.

        ``custom_data``: string entries written to ``metadata.yaml``'s ``custom_data``.
        ``flag``: how messages name ``overwrite`` (``overwrite:=true`` for the recorder).
        """
        self.path = Path(path)
        self.overwrite = overwrite
        self.flag = flag
        self.chunk_bytes = chunk_bytes
        self.split_duration_ns = split_duration_ns
        self.split_bytes = split_bytes
        self.custom_data = dict(custom_data or {})
        self._topics: dict[str, _Topic] = {}
        self._files: list[_FileStats] = []
        self._stream: _DirectFile | None = None
        self._mcap: McapWriter | None = None
        self._schemas: dict[str, int] = {}
        #: Per topic, messages in the file (handed over in a finished chunk without error).
        self.on_disk: dict[str, int] = {}
        self._pending: dict[str, int] = {}
        #: The failed write that stopped the writer, or None.
        self.failure: BagError | None = None
        self._lock = contextlib.ExitStack()

    # -- life cycle -------------------------------------------------------------------------------
    def open(self) -> Self:
        """Lock the bag, create the folder and the first MCAP file.

        An existing folder is written only when empty, or replaced when it holds a bag and
        ``overwrite`` is set (``outputs.check_bag_output``): never another command's result.
        When the first file cannot be started (a disk already full), what was created is
        removed: no empty file is left to look like a torn bag.

        Raises:
            OutputError: the folder is refused (one line naming it and what it holds), or
                another process writes it (named by its pid).
            BagError: creating the folder or the first file failed (the OS's reason).
        """
        try:
            self.path = self._lock.enter_context(
                bag_output(self.path, overwrite=self.overwrite, flag=self.flag)
            )
            self._create()
        except BaseException:
            self._lock.close()
            raise
        return self

    def _create(self) -> None:
        """The folder and the first file; on failure, the folder as ``open`` found it."""
        created = not self.path.exists()
        try:
            if self.path.is_dir() and any(self.path.iterdir()):
                shutil.rmtree(self.path)  # a bag, and overwrite is set
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise BagError(f'{self.path}: {os_reason(err)} (creating the bag folder)') from err
        try:
            self._start_file()
        except (OSError, ValueError) as err:
            if self._stream is not None:
                self._stream.close()
            self._mcap = self._stream = None
            with contextlib.suppress(OSError):
                (self.path / self._files[-1].path).unlink(missing_ok=True)
                if created:
                    self.path.rmdir()
            reason = os_reason(err) if isinstance(err, OSError) else str(err)
            raise BagError(
                f'{self.path}: writing failed: {reason} (starting {self._files[-1].path}); '
                'nothing was written'
            ) from err

    def __enter__(self) -> Self:
        return self.open()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def _start_file(self) -> None:
        name = f'{self.path.name}_{len(self._files)}.mcap'
        self._files.append(_FileStats(path=name))
        self._stream = _DirectFile(self.path / name)
        stream: Any = self._stream  # a file-like object, as MCAP's writer takes it
        self._mcap = McapWriter(
            stream,
            chunk_size=self.chunk_bytes,
            compression=CompressionType.ZSTD,
        )
        self._mcap.start(profile='ros2', library='id_learning')
        self._schemas = {}
        for topic in self._topics.values():
            topic.channel_id = self._register(topic.name, topic.msgtype)

    def _finish_file(self) -> None:
        if self._mcap is not None and self._stream is not None:
            self._mcap.finish()
            self._stream.close()
        self._mcap = None
        self._stream = None

    def close(self) -> None:
        """Finish the MCAP file(s) and write ``metadata.yaml``.

        A writer stopped by a failed write only closes its file: the bag is left for
        ``id-learning bag recover``.

        Raises:
            BagError: finishing the file or writing ``metadata.yaml`` failed (the OS's reason).
        """
        try:
            if self.failure is not None:
                if self._stream is not None:
                    self._stream.close()
                self._mcap = self._stream = None
                return
            if self._mcap is None:
                return
            self._guarded(self._finish_file)
            self._confirm()
            self._guarded(
                lambda: write_metadata(
                    self.path,
                    [(t.name, t.msgtype, t.type_hash, t.count) for t in self._topics.values()],
                    [(f.path, f.first_ns or 0, f.last_ns or 0, f.count) for f in self._files],
                    self.custom_data,
                )
            )
        finally:
            self._lock.close()

    def flush(self) -> None:
        """Finish the chunk in progress and push everything written so far to the file.

        After a flush the messages survive the process being killed (a recovery rebuilds the
        index) and count in ``on_disk``. Each flush ends a compressed chunk, so flushing often
        costs compression ratio.

        Raises:
            BagError: the write failed; the writer is stopped (see the module docstring).
        """
        if self._mcap is not None:
            mcap = self._mcap
            self._guarded(mcap.flush)
            self._confirm()

    def _confirm(self) -> None:
        """The messages of the chunks handed over are in the file."""
        for topic, count in self._pending.items():
            self.on_disk[topic] = self.on_disk.get(topic, 0) + count
        self._pending = dict.fromkeys(self._pending, 0)

    def _guarded(self, step: Callable[[], _T]) -> _T:
        """Run a step that writes; a failure stops the writer and raises ``BagError``."""
        if self.failure is not None:
            raise self.failure
        try:
            return step()
        except (OSError, ValueError) as err:
            reason = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
            lost = sum(self._pending.values())
            self.failure = BagWriteError(
                reason,
                f'{self.path}: writing failed: {reason}; nothing more is written: the '
                f'{sum(self.on_disk.values())} message(s) already in the file are kept '
                f'(id-learning bag recover), the {lost} of the chunk being written did not all '
                'reach it',
            )
            if self._stream is not None:
                self._stream.close()
            self._mcap = self._stream = None
            raise self.failure from err

    # -- topics and messages ----------------------------------------------------------------------
    def _register(self, topic: str, msgtype: str) -> int:
        assert self._mcap is not None
        if msgtype not in self._schemas:
            text, _ = message_definition(msgtype)
            self._schemas[msgtype] = self._mcap.register_schema(
                name=msgtype, encoding='ros2msg', data=text.encode()
            )
        return self._mcap.register_channel(
            topic=topic,
            message_encoding='cdr',
            schema_id=self._schemas[msgtype],
            metadata={'offered_qos_profiles': ''},
        )

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic before writing to it."""
        if self._mcap is None:
            raise BagError(f'{self.path}: writer is not open')
        if topic in self._topics:
            raise BagError(f'{self.path}: topic {topic} declared twice')
        _, type_hash = message_definition(msgtype)
        self._topics[topic] = _Topic(topic, msgtype, type_hash, self._register(topic, msgtype))

    def write(self, topic: str, log_time_ns: int, data: bytes | memoryview) -> None:
        """Append one serialized message; log_time_ns is the time it was received [ns].

        The message is in the file (``on_disk``) once its chunk is: when the chunk is full, on
        ``flush`` or on ``close``.

        Raises:
            BagError: the writer is not open, the topic was not declared, or a write failed
                (now or before: the writer is stopped).
        """
        if self.failure is not None:
            raise self.failure
        if self._mcap is None:
            raise BagError(f'{self.path}: writer is not open')
        entry = self._topics.get(topic)
        if entry is None:
            raise BagError(f'{self.path}: topic {topic} was not declared with add_topic')
        current = self._files[-1]
        if self._should_split(current, log_time_ns):
            self._guarded(self._split)
            self._confirm()
            current = self._files[-1]
        self._pending[topic] = self._pending.get(topic, 0) + 1
        assert self._mcap is not None
        assert self._stream is not None
        mcap, before = self._mcap, self._stream.tell()
        self._guarded(
            lambda: mcap.add_message(
                channel_id=entry.channel_id,
                log_time=log_time_ns,
                publish_time=log_time_ns,
                data=bytes(data),
                sequence=entry.count,
            )
        )
        if self._stream.tell() != before:  # a full chunk, this message in it, was written
            self._confirm()
        entry.count += 1
        current.count += 1
        current.first_ns = (
            log_time_ns if current.first_ns is None else min(current.first_ns, log_time_ns)
        )
        current.last_ns = (
            log_time_ns if current.last_ns is None else max(current.last_ns, log_time_ns)
        )

    def _split(self) -> None:
        self._finish_file()
        self._start_file()

    def _should_split(self, current: _FileStats, log_time_ns: int) -> bool:
        if current.count == 0:
            return False
        if (
            self.split_duration_ns is not None
            and current.first_ns is not None
            and log_time_ns - current.first_ns >= self.split_duration_ns
        ):
            return True
        if self.split_bytes is not None and self._stream is not None:
            return self._stream.tell() >= self.split_bytes
        return False
