"""The record-by-record scan of one .mcap file that ``recover`` rebuilds a bag from.

A chunk whose data does not decode (a CRC mismatch, a damaged stream) but whose record framing
holds (its opcode and length lead to the next record) is skipped, named and counted, and the scan
goes on after it. It stops at the first record that is incomplete or whose framing is broken; a
chunk torn by the cut is decompressed as a stream as far as it goes (zstd, lz4 or none) and its
complete records kept.
"""

from __future__ import annotations

import logging
import os
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Footer, McapRecord, Message, MessageIndex, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from id_learning.bag.reader import TopicInfo
from id_learning.errors import BagError

__all__ = [
    'DAMAGED_SUFFIX',
    'MCAP_MAGIC',
    'FileScan',
    'MessageSink',
    'SkippedChunk',
    'Topics',
    'scan_file',
]

_LOG = logging.getLogger(__name__)

MCAP_MAGIC = b'\x89MCAP0\r\n'
DAMAGED_SUFFIX = '.damaged'
# What a damaged record or chunk raises while being parsed or decompressed (CRC errors are
# ValueErrors; truncated fixed-size fields are struct errors).
_DAMAGE = (McapError, struct.error, ValueError, zstandard.ZstdError)
# What lz4's frame decoder raises on a damaged frame.
_LZ4_DAMAGE = (RuntimeError, ValueError)
# Records that may follow a chunk: any MCAP defines but the header.
_NEXT_OPCODES = frozenset(op.value for op in Opcode) - {Opcode.HEADER.value}


def _iso(stamp_ns: int) -> str:
    """A log time as UTC ISO 8601, or in ns where no calendar date holds it."""
    try:
        moment = datetime.fromtimestamp(stamp_ns / 1e9, tz=UTC)
    except (OverflowError, OSError, ValueError):
        return f'{stamp_ns} ns'
    return moment.isoformat(timespec='milliseconds').replace('+00:00', 'Z')


@dataclass(frozen=True)
class SkippedChunk:
    """A chunk whose data did not decode but whose framing did: skipped, the records after kept.

    Attributes:
        offset: byte offset of its opcode in the file.
        length_bytes: its bytes, opcode and length field included (all discarded).
        compression: its compression ('' for none, 'unknown' where its fields do not parse).
        reason: why its data did not decode (a CRC mismatch, a damaged stream).
        header_ns: the (first, last) message log times its header gives, or None where they
            cannot be right (the last before the first: the header is damaged too).
        kept_before_ns: log time of the last message kept before it, or None.
        kept_after_ns: log time of the first message kept after it, or None.
        messages_lost: messages the message index records after it list, or None where none
            follow it (a writer's option in MCAP).
    """

    offset: int
    length_bytes: int
    compression: str
    reason: str
    header_ns: tuple[int, int] | None
    kept_before_ns: int | None = None
    kept_after_ns: int | None = None
    messages_lost: int | None = None

    def describe(self) -> str:
        """Which chunk, where, why, and the log times lost with it as far as they can be told."""
        lost = (
            'its messages' if self.messages_lost is None else f'its {self.messages_lost} messages'
        )
        if self.header_ns is not None:
            lost += f' (log times {_iso(self.header_ns[0])} to {_iso(self.header_ns[1])})'
        else:
            lost += ' (log times unknown: its header is damaged too)'
        around = [
            'nothing kept before it'
            if self.kept_before_ns is None
            else f'the last message kept before it is at {_iso(self.kept_before_ns)}',
            'nothing kept after it'
            if self.kept_after_ns is None
            else f'the first after it at {_iso(self.kept_after_ns)}',
        ]
        return (
            f'damaged chunk ({self.compression or "uncompressed"}) at byte {self.offset} '
            f'({self.length_bytes} bytes) skipped: {self.reason}; {lost} are lost; '
            + ', '.join(around)
        )


@dataclass(frozen=True)
class FileScan:
    """What the scan of one ``.mcap`` file found.

    Attributes:
        name: file name inside the bag folder.
        size_bytes: file size [bytes].
        valid_bytes: offset just past the last complete record [bytes].
        messages: complete messages found.
        is_complete: the file ends with its footer and closing magic (the writer finished it)
            and no chunk was skipped.
        stop_reason: why the scan stopped before the footer, or None.
        undecoded: what the scan left that a better reader might still decode (a damaged
            chunk, a compression it cannot stream), or None: the originals are then kept.
        skipped: damaged chunks skipped, in file order.
        orphaned_messages: messages after a skipped chunk that name a channel only it declared
            (the file has no readable summary to declare it again): dropped.
    """

    name: str
    size_bytes: int
    valid_bytes: int
    messages: int
    is_complete: bool
    stop_reason: str | None = None
    undecoded: str | None = None
    skipped: tuple[SkippedChunk, ...] = ()
    orphaned_messages: int = 0

    @property
    def bytes_discarded(self) -> int:
        """Bytes lost: after the last complete record (the torn tail), and in skipped chunks."""
        return self.size_bytes - self.valid_bytes + sum(c.length_bytes for c in self.skipped)

    def state(self) -> str:
        """'complete', or what kept the file from it (chunks skipped, the torn tail)."""
        if self.is_complete:
            return 'complete'
        parts = [f'{len(self.skipped)} damaged chunk(s) skipped'] if self.skipped else []
        if self.orphaned_messages:
            parts.append(
                f'{self.orphaned_messages} messages after them dropped (their channel was '
                'declared only in a skipped chunk)'
            )
        if self.stop_reason or not parts:
            parts.append(f'torn ({self.stop_reason or "no footer"})')
        return ', '.join(parts)


@dataclass
class Topics:
    """Topics seen over all files of a bag: channel ids are per file, topic names are not."""

    msgtypes: dict[str, str] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    schema_texts: dict[str, bytes] = field(default_factory=dict)

    def add(self, file: Path, topic: str, msgtype: str, schema_text: bytes) -> None:
        """Record a channel of ``file``; a topic of two types in one bag is refused."""
        known = self.msgtypes.get(topic)
        if known is None:
            self.msgtypes[topic] = msgtype
            self.counts[topic] = 0
            self.schema_texts.setdefault(msgtype, schema_text)
        elif known != msgtype:
            raise BagError(
                f'{file}: topic {topic} has type {msgtype} here and {known} in an earlier file'
            )

    def infos(self) -> tuple[TopicInfo, ...]:
        """Each topic with its type and the messages kept."""
        return tuple(
            TopicInfo(name, kind, self.counts[name]) for name, kind in self.msgtypes.items()
        )


MessageSink = Callable[[str, int, bytes], None]


class _Bounded:
    """A binary stream whose reads never ask for more than the file has left.

    A damaged length field can claim exabytes; reading it as is would raise MemoryError or
    OverflowError. Clamped, the read comes back short and the record counts as torn.
    """

    def __init__(self, stream: BinaryIO, size: int) -> None:
        self._stream = stream
        self._size = size

    def read(self, length: int = -1) -> bytes:
        left = self._size - self._stream.tell()
        return self._stream.read(left if length < 0 else min(length, left))

    def tell(self) -> int:
        return self._stream.tell()


@dataclass(frozen=True)
class _TornChunk:
    """What the stream decode of a chunk cut short gave back.

    Attributes:
        records: the records complete within its decodable part, in order.
        compression: the chunk's compression ('' for none).
        undecoded: why its data could not be decoded as far as the file goes, or None.
    """

    records: list[McapRecord]
    compression: str
    undecoded: str | None = None


def _stream_decode(compression: str, compressed: bytes) -> tuple[bytes, str | None]:
    """Decompress a cut stream as far as it goes: (the data, why it stopped early or None)."""
    if compression == '':
        return compressed, None
    if compression == 'zstd':
        try:
            return zstandard.ZstdDecompressor().decompressobj().decompress(compressed), None
        except zstandard.ZstdError as err:
            return b'', f'zstd data damaged ({err})'
    if compression == 'lz4':
        # Frame by frame, block by block: each complete block comes out, the cut one stays in.
        decoder = lz4.frame.LZ4FrameDecompressor()
        try:
            return decoder.decompress(compressed), None
        except _LZ4_DAMAGE as err:
            return b'', f'lz4 data damaged ({err})'
    return b'', f'compression {compression!r} cannot be decoded as a stream here'


def _torn_chunk_records(raw: bytes) -> _TornChunk:
    """The records complete within a chunk record cut short (``raw`` from its opcode on).

    Chunk layout: opcode, length (u64), start and end time (u64 each), uncompressed size (u64),
    CRC (u32), compression (u32 length + text), records (u64 length + bytes).
    """
    fixed = struct.Struct('<BQQQQI')
    if len(raw) < fixed.size + 4 or raw[0] != Opcode.CHUNK.value:
        return _TornChunk([], '')
    pos = fixed.size
    (name_length,) = struct.unpack_from('<I', raw, pos)
    pos += 4
    compression = raw[pos : pos + name_length].decode('utf-8', errors='replace')
    pos += name_length + 8  # the records' byte length follows the name
    data, undecoded = _stream_decode(compression, raw[pos:])
    readers: dict[int, Callable[[ReadDataStream], McapRecord]] = {
        Opcode.SCHEMA.value: Schema.read,
        Opcode.CHANNEL.value: Channel.read,
    }
    records: list[McapRecord] = []
    at = 0
    while at + 9 <= len(data):
        opcode = data[at]
        (length,) = struct.unpack_from('<Q', data, at + 1)
        end = at + 9 + length
        if end > len(data):
            break  # the record the cut went through
        stream = ReadDataStream(BytesIO(data[at + 9 : end]))
        try:
            if opcode == Opcode.MESSAGE.value:
                records.append(Message.read(stream, length))
            elif opcode in readers:
                records.append(readers[opcode](stream))
        except _DAMAGE as err:
            undecoded = f'a record at byte {at} of its data does not decode ({err})'
            break
        at = end
    return _TornChunk(records, compression, undecoded)


class _BrokenFramingError(Exception):
    """The records after a damaged chunk cannot be found: the scan stops there."""


def _chunk_framing(stream: BinaryIO, at: int, size: int) -> tuple[int, tuple[int, int] | None]:
    """Where the chunk record at byte ``at`` ends, and the log times its header gives.

    The framing holds when the record at ``at`` is a chunk ending within the file, and the
    record after it starts with an opcode MCAP defines and a length that fits in the file (or the
    file ends with the chunk). A damaged length field points into other data, where both hold by
    chance all but never.

    Raises:
        _BrokenFramingError: the framing does not hold (what is wrong).
    """
    fd = stream.fileno()
    head = os.pread(fd, 9 + 16, at)
    if len(head) < 9 + 16 or head[0] != Opcode.CHUNK.value:
        raise _BrokenFramingError('no chunk record starts there')
    length, first, last = struct.unpack_from('<QQQ', head, 1)
    end = at + 9 + length
    if end > size:
        raise _BrokenFramingError(
            f'its length field ({length} bytes) runs past the end of the file'
        )
    after = os.pread(fd, 9, end)
    if len(after) == 9:
        (next_length,) = struct.unpack_from('<Q', after, 1)
        if after[0] not in _NEXT_OPCODES or end + 9 + next_length > size:
            raise _BrokenFramingError(
                f'no record starts at byte {end}, where its length field ends it'
            )
    return end, ((first, last) if first <= last else None)


class _Scanner:
    """One file's scan: the declarations seen, the messages kept, the chunks skipped."""

    def __init__(
        self, file: Path, topics: Topics, sink: MessageSink | None, stream: BinaryIO, size: int
    ) -> None:
        self.file = file
        self.topics = topics
        self.sink = sink
        self.stream = stream
        self.size = size
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, tuple[str, str]] = {}
        self.messages = 0
        self.skipped: list[SkippedChunk] = []
        self.orphaned = 0
        self.footer_seen = False
        self._last_ns: int | None = None
        self._indexing = False  # the records read since the last chunk skipped are its index
        self._summary: tuple[dict[int, Schema], dict[int, Channel]] | None = None

    def records(self) -> Iterator[McapRecord]:
        """The records from the stream's position on, chunks as they are.

        Magic checked before; the closing magic after the footer is still read and checked. No
        record size limit: a record longer than what is left is the torn tail, and the bounded
        stream turns it into a short read instead of a huge allocation.
        """
        reader = StreamReader(
            _Bounded(self.stream, self.size),  # type: ignore[arg-type]  # duck-typed: read() is all it uses
            skip_magic=True,
            emit_chunks=True,
            record_size_limit=None,
        )
        return reader.records

    def take(self, record: object) -> None:
        """Keep a schema, channel or message; pass a message to the sink."""
        if isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Channel):
            self._declare(record, self.schemas)
        elif isinstance(record, Message):
            channel = self.channels.get(record.channel_id)
            if channel is None and self.skipped:
                schemas, channels = self._summary_declarations()
                if record.channel_id not in channels:  # declared in a skipped chunk only
                    self.orphaned += 1
                    return
                self._declare(channels[record.channel_id], {**schemas, **self.schemas})
                channel = self.channels[record.channel_id]
            if channel is None:
                raise BagError(
                    f'{self.file}: message at log time {record.log_time} ns names channel '
                    f'{record.channel_id}, which the file never declares'
                )
            self.topics.counts[channel[0]] += 1
            self.messages += 1
            if self.skipped and self.skipped[-1].kept_after_ns is None:
                self.skipped[-1] = replace(self.skipped[-1], kept_after_ns=record.log_time)
            self._last_ns = record.log_time
            if self.sink is not None:
                self.sink(channel[0], record.log_time, record.data)
        elif isinstance(record, Footer):
            self.footer_seen = True
        if isinstance(record, MessageIndex) and self._indexing:  # the skipped chunk's index
            lost = self.skipped[-1].messages_lost or 0
            self.skipped[-1] = replace(self.skipped[-1], messages_lost=lost + len(record.records))
        else:
            self._indexing = False

    def skip(self, at: int, compression: str, reason: str) -> str | None:
        """Skip the damaged chunk at byte ``at`` where its framing holds; else why it does not.

        Skipped, the stream is left at the record after it.
        """
        try:
            end, header_ns = _chunk_framing(self.stream, at, self.size)
        except _BrokenFramingError as err:
            return str(err)
        chunk = SkippedChunk(at, end - at, compression, reason, header_ns, self._last_ns)
        self.skipped.append(chunk)
        self._indexing = True
        self.stream.seek(end)
        return None

    def _declare(self, record: Channel, schemas: dict[int, Schema]) -> None:
        schema = schemas.get(record.schema_id)
        if schema is None or record.message_encoding != 'cdr':
            raise BagError(
                f'{self.file}: topic {record.topic} has no schema or encoding '
                f'{record.message_encoding!r}; only CDR messages of ROS 2 types are recovered'
            )
        self.topics.add(self.file, record.topic, schema.name, schema.data)
        self.channels[record.id] = (record.topic, schema.name)

    def _summary_declarations(self) -> tuple[dict[int, Schema], dict[int, Channel]]:
        """The schemas and channels of the file's summary section (read once; none if unreadable).

        A skipped chunk may have held the data section's only declaration of the channels the
        messages after it name (MCAP writers declare each once); a finished file repeats them in
        its summary.
        """
        if self._summary is None:
            self._summary = ({}, {})
            at = self.stream.tell()
            try:
                self.stream.seek(0)  # the reader checks the magic where it starts
                summary = SeekingReader(self.stream, record_size_limit=self.size).get_summary()
            except (*_DAMAGE, OSError):
                summary = None
            finally:
                self.stream.seek(at)
            if summary is not None:
                self._summary = (dict(summary.schemas), dict(summary.channels))
        return self._summary

    def torn_tail(self, valid: int) -> tuple[str, str | None]:
        """Keep what the chunk cut by the end of the file holds: (stop reason, undecoded)."""
        self.stream.seek(valid)
        torn = _torn_chunk_records(self.stream.read())
        before = self.messages
        for item in torn.records:
            self.take(item)
        if not (torn.records or torn.undecoded):
            return 'file ends inside a record', None
        where = f'the {torn.compression or "uncompressed"} chunk at byte {valid}'
        kept = self.messages - before
        reason = f'file ends inside {where}; {kept} messages kept from its complete part'
        if torn.undecoded:
            return f'{reason} ({torn.undecoded})', f'{where} is cut and {torn.undecoded}'
        return reason, None

    def run(self) -> FileScan:
        """Scan from after the magic to the footer, or to where the file or its framing ends."""
        valid = self.stream.tell()
        stop_reason: str | None = None
        undecoded: str | None = None
        records = self.records()
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except _DAMAGE as err:
                # A chunk whose own fields do not parse, in a framing that holds: skipped.
                reason = f'{err or type(err).__name__}'
                if self.skip(valid, 'unknown', reason) is None:
                    valid = self.stream.tell()
                    records = self.records()
                    continue
                # Truncation shows as EndOfFile, or as a struct error in a short fixed-size field.
                if isinstance(err, EndOfFile) or self.stream.tell() >= self.size:
                    stop_reason, undecoded = self.torn_tail(valid)
                else:
                    stop_reason = undecoded = f'damaged record at byte {valid}: {reason}'
                break
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except (*_DAMAGE, *_LZ4_DAMAGE) as err:
                    reason = f'{err or type(err).__name__}'
                    broken = self.skip(valid, record.compression, reason)
                    if broken is None:
                        valid = self.stream.tell()
                        records = self.records()
                        continue
                    stop_reason = undecoded = (
                        f'damaged chunk ({record.compression or "uncompressed"}) at byte '
                        f'{valid}: {reason}; {broken}, so nothing after it is read'
                    )
                    break
                for item in inner:
                    self.take(item)
            else:
                self.take(record)
            valid = self.stream.tell()
        if stop_reason is None:
            valid = self.stream.tell()
        if self.skipped:
            first = self.skipped[0].offset
            skipped = f'{len(self.skipped)} damaged chunk(s) skipped, the first at byte {first}'
            undecoded = f'{skipped}; {undecoded}' if undecoded else skipped
        return FileScan(
            name=self.file.name,
            size_bytes=self.size,
            valid_bytes=valid,
            messages=self.messages,
            is_complete=self.footer_seen and stop_reason is None and not self.skipped,
            stop_reason=stop_reason,
            undecoded=undecoded,
            skipped=tuple(self.skipped),
            orphaned_messages=self.orphaned,
        )


def scan_file(file: Path, topics: Topics, sink: MessageSink | None) -> FileScan:
    """Read the complete records of one MCAP file; pass each message to sink in file order.

    A chunk whose data does not decode is skipped where its framing holds (``_chunk_framing``)
    and the scan goes on after it; otherwise the scan stops at the first record that is
    incomplete or does not decode.
    """
    size = file.stat().st_size
    with file.open('rb') as stream:
        head = stream.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC[: len(head)]:
            raise BagError(f'{file}: not an MCAP file (starts with {head!r})')
        if len(head) < len(MCAP_MAGIC):
            reason = 'empty file' if not head else 'file ends inside the MCAP magic'
            return FileScan(file.name, size, 0, 0, is_complete=False, stop_reason=reason)
        return _Scanner(file, topics, sink, stream, size).run()
