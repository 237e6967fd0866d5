"""rosbag2 writer with MCAP storage: a folder with ``metadata.yaml`` and ``.mcap`` file(s).

Messages are stored as serialized CDR bytes, as they came (no re-serialization). MCAP chunks are
zstd-compressed; a small chunk size bounds what a crash can lose, since everything up to the last
finished chunk is on disk.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import BinaryIO, Self

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from id_learning.bag.messages import message_definition
from id_learning.errors import BagError

__all__ = ['BagWriter', 'write_metadata']

ROSBAG2_VERSION = 9
DEFAULT_CHUNK_BYTES = 1 << 20


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
    tmp.write_text(text, encoding='utf-8')
    tmp.replace(bag_dir / 'metadata.yaml')


class BagWriter:
    """Write serialized messages to a rosbag2 MCAP bag folder.

    Use as a context manager; ``metadata.yaml`` is written on close. Optional splitting starts a
    new ``.mcap`` file once the current one spans ``split_duration_ns`` or holds ``split_bytes``.
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
    ) -> None:
        """Prepare a bag folder; nothing is written before ``open()``.

        ``custom_data``: string entries written to ``metadata.yaml``'s ``custom_data``.
        """
        self.path = Path(path)
        self.overwrite = overwrite
        self.chunk_bytes = chunk_bytes
        self.split_duration_ns = split_duration_ns
        self.split_bytes = split_bytes
        self.custom_data = dict(custom_data or {})
        self._topics: dict[str, _Topic] = {}
        self._files: list[_FileStats] = []
        self._stream: BinaryIO | None = None
        self._mcap: McapWriter | None = None
        self._schemas: dict[str, int] = {}

    # -- life cycle -------------------------------------------------------------------------------
    def open(self) -> Self:
        """Create the folder and the first MCAP file.

        Raises:
            BagError: the folder exists and overwrite is False.
        """
        if self.path.exists():
            if not self.overwrite:
                raise BagError(f'{self.path}: bag folder already exists (pass overwrite/--force)')
            shutil.rmtree(self.path)
        self.path.mkdir(parents=True)
        self._start_file()
        return self

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
        self._stream = (self.path / name).open('wb')
        self._mcap = McapWriter(
            self._stream,
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
        """Finish the MCAP file(s) and write ``metadata.yaml``."""
        if self._mcap is None:
            return
        self._finish_file()
        write_metadata(
            self.path,
            [(t.name, t.msgtype, t.type_hash, t.count) for t in self._topics.values()],
            [(f.path, f.first_ns or 0, f.last_ns or 0, f.count) for f in self._files],
            self.custom_data,
        )

    def flush(self) -> None:
        """Finish the chunk in progress and push everything written so far to the file.

        After a flush the messages survive the process being killed (a recovery rebuilds the
        index). Each flush ends a compressed chunk, so flushing often costs compression ratio.
        """
        if self._mcap is not None:
            self._mcap.flush()

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
        """Append one serialized message; log_time_ns is the time it was received [ns]."""
        if self._mcap is None:
            raise BagError(f'{self.path}: writer is not open')
        entry = self._topics.get(topic)
        if entry is None:
            raise BagError(f'{self.path}: topic {topic} was not declared with add_topic')
        current = self._files[-1]
        if self._should_split(current, log_time_ns):
            self._finish_file()
            self._start_file()
            current = self._files[-1]
        self._mcap.add_message(
            channel_id=entry.channel_id,
            log_time=log_time_ns,
            publish_time=log_time_ns,
            data=bytes(data),
            sequence=entry.count,
        )
        entry.count += 1
        current.count += 1
        current.first_ns = (
            log_time_ns if current.first_ns is None else min(current.first_ns, log_time_ns)
        )
        current.last_ns = (
            log_time_ns if current.last_ns is None else max(current.last_ns, log_time_ns)
        )

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
