"""The record-by-record scan of one .mcap file that ``recover`` rebuilds a bag from.

It stops at the first record that is incomplete or does not decode; a chunk torn by the cut is
decompressed as a stream as far as it goes (zstd, lz4 or none) and its complete records kept.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, McapRecord, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from id_learning.bag.reader import TopicInfo
from id_learning.errors import BagError

__all__ = ['DAMAGED_SUFFIX', 'MCAP_MAGIC', 'FileScan', 'MessageSink', 'Topics', 'scan_file']

_LOG = logging.getLogger(__name__)

MCAP_MAGIC = b'\x89MCAP0\r\n'
DAMAGED_SUFFIX = '.damaged'
# What a damaged record or chunk raises while being parsed or decompressed (CRC errors are
# ValueErrors; truncated fixed-size fields are struct errors).
_DAMAGE = (McapError, struct.error, ValueError, zstandard.ZstdError)
# What lz4's frame decoder raises on a damaged frame.
_LZ4_DAMAGE = (RuntimeError, ValueError)


@dataclass(frozen=True)
class FileScan:
    """What the scan of one ``.mcap`` file found.

    Attributes:
        name: file name inside the bag folder.
        size_bytes: file size [bytes].
        valid_bytes: offset just past the last complete record [bytes].
        messages: complete messages found.
        is_complete: the file ends with its footer and closing magic (the writer finished it).
        stop_reason: why the scan stopped before the footer, or None.
        undecoded: what the scan left that a better reader might still decode (a damaged
            chunk, a compression it cannot stream), or None: the originals are then kept.
    """

    name: str
    size_bytes: int
    valid_bytes: int
    messages: int
    is_complete: bool
    stop_reason: str | None = None
    undecoded: str | None = None

    @property
    def bytes_discarded(self) -> int:
        """Bytes after the last complete record, lost with the torn tail."""
        return self.size_bytes - self.valid_bytes


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


def scan_file(file: Path, topics: Topics, sink: MessageSink | None) -> FileScan:
    """Read the complete records of one MCAP file; pass each message to sink in file order."""
    size = file.stat().st_size
    with file.open('rb') as stream:
        head = stream.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC[: len(head)]:
            raise BagError(f'{file}: not an MCAP file (starts with {head!r})')
        if len(head) < len(MCAP_MAGIC):
            reason = 'empty file' if not head else 'file ends inside the MCAP magic'
            return FileScan(file.name, size, 0, 0, is_complete=False, stop_reason=reason)
        schemas: dict[int, Schema] = {}
        channels: dict[int, tuple[str, str]] = {}
        messages = 0
        valid = stream.tell()
        footer_seen = False
        stop_reason: str | None = None
        undecoded: str | None = None

        def take(record: object) -> None:
            nonlocal messages
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                schema = schemas.get(record.schema_id)
                if schema is None or record.message_encoding != 'cdr':
                    raise BagError(
                        f'{file}: topic {record.topic} has no schema or encoding '
                        f'{record.message_encoding!r}; only CDR messages of ROS 2 types are '
                        'recovered'
                    )
                topics.add(file, record.topic, schema.name, schema.data)
                channels[record.id] = (record.topic, schema.name)
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    raise BagError(
                        f'{file}: message at log time {record.log_time} ns names channel '
                        f'{record.channel_id}, which the file never declares'
                    )
                topics.counts[channel[0]] += 1
                messages += 1
                if sink is not None:
                    sink(channel[0], record.log_time, record.data)

        # Magic checked above; the closing magic after the footer is still read and checked.
        # No record size limit: a record longer than what is left is the torn tail, and the
        # bounded stream turns it into a short read instead of a huge allocation.
        reader = StreamReader(
            _Bounded(stream, size),  # type: ignore[arg-type]  # duck-typed: read() is all it uses
            skip_magic=True,
            emit_chunks=True,
            record_size_limit=None,
        )
        records = reader.records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except _DAMAGE as err:
                # Truncation shows as EndOfFile, or as a struct error in a short fixed-size field.
                at_end = isinstance(err, EndOfFile) or stream.tell() >= size
                stop_reason = (
                    'file ends inside a record'
                    if at_end
                    else f'damaged record at byte {valid}: {err or type(err).__name__}'
                )
                if not at_end:
                    undecoded = stop_reason
                else:
                    stream.seek(valid)
                    torn = _torn_chunk_records(stream.read())
                    before = messages
                    for item in torn.records:
                        take(item)
                    if torn.records or torn.undecoded:
                        where = f'the {torn.compression or "uncompressed"} chunk at byte {valid}'
                        stop_reason = (
                            f'file ends inside {where}; {messages - before} messages kept from '
                            'its complete part'
                        )
                        if torn.undecoded:
                            undecoded = f'{where} is cut and {torn.undecoded}'
                            stop_reason += f' ({torn.undecoded})'
                break
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except (*_DAMAGE, *_LZ4_DAMAGE) as err:
                    stop_reason = (
                        f'damaged chunk ({record.compression or "uncompressed"}) at byte '
                        f'{valid}: {err or type(err).__name__}'
                    )
                    undecoded = stop_reason
                    break
                for item in inner:
                    take(item)
            else:
                take(record)
                footer_seen = footer_seen or isinstance(record, Footer)
            valid = stream.tell()
        if stop_reason is None:
            valid = stream.tell()
    return FileScan(
        name=file.name,
        size_bytes=size,
        valid_bytes=valid,
        messages=messages,
        is_complete=footer_seen and stop_reason is None,
        stop_reason=stop_reason,
        undecoded=undecoded,
    )
