"""recover_bag on bags with a damaged chunk in the middle: the chunks after it are kept.

A chunk whose compressed data is damaged (bytes flipped on disk) fails its CRC or its decoder, but
its opcode and length still lead to the next record: recovery skips it, names it (offset, reason,
log times, messages lost) and goes on. Only where the framing itself is broken does it stop there.
What each chunk holds is read apart from ``recover``, from the intact file's summary.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import MessageIndex

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, iter_raw
from id_learning.bag.recover import recover_bag
from id_learning.errors import BagError

TOPICS = ('/joint_states', '/motor_currents')
JOINTS = ('joint_1', 'joint_2', 'joint_3')
N_SAMPLES = 600
PERIOD_NS = 8_000_000
T0_NS = 1_767_225_600 * 1_000_000_000

Messages = dict[str, list[tuple[int, bytes]]]


@dataclass(frozen=True)
class ChunkInfo:
    """One chunk of the intact file, from its chunk index and message index records."""

    offset: int
    length: int
    first_ns: int
    last_ns: int
    counts: dict[str, int]  # messages per topic


def write_bag(path: Path) -> Messages:
    """A finished two-topic bag in small zstd chunks; each topic's (log time, bytes)."""
    rng = np.random.default_rng(11)
    empty = np.zeros(0)
    written: Messages = {topic: [] for topic in TOPICS}
    with BagWriter(path, chunk_bytes=8192) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, JOINT_STATE)
        for k in range(N_SAMPLES):
            stamp = T0_NS + k * PERIOD_NS
            q, v, i = rng.normal(size=(3, len(JOINTS)))
            for topic, data in (
                (TOPICS[0], encode_joint_state(stamp, JOINTS, q, v, empty)),
                (TOPICS[1], encode_joint_state(stamp, JOINTS, empty, empty, i)),
            ):
                writer.write(topic, stamp, data)
                written[topic].append((stamp, data))
    return written


@pytest.fixture(scope='module')
def intact(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Messages, list[ChunkInfo]]:
    path = tmp_path_factory.mktemp('intact') / 'bag'
    written = write_bag(path)
    (file,) = path.glob('*.mcap')
    with file.open('rb') as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None
        topic_of = {cid: channel.topic for cid, channel in summary.channels.items()}
        chunks = []
        for index in summary.chunk_indexes:
            counts = dict.fromkeys(TOPICS, 0)
            for cid, offset in index.message_index_offsets.items():
                stream.seek(offset + 9)  # opcode (1) and record length (8)
                counts[topic_of[cid]] += len(MessageIndex.read(ReadDataStream(stream)).records)
            chunks.append(
                ChunkInfo(
                    index.chunk_start_offset,
                    index.chunk_length,
                    index.message_start_time,
                    index.message_end_time,
                    counts,
                )
            )
    assert len(chunks) >= 5  # precondition: chunks before and after the damaged one
    return path, written, chunks


def damaged_copy(source: Path, target: Path, chunk: ChunkInfo) -> Path:
    """Copy the bag with 64 bytes flipped in the middle of ``chunk``'s compressed data."""
    shutil.copytree(source, target)
    (file,) = target.glob('*.mcap')
    data = bytearray(file.read_bytes())
    middle = chunk.offset + chunk.length // 2
    data[middle : middle + 64] = bytes(b ^ 0xFF for b in data[middle : middle + 64])
    file.write_bytes(bytes(data))
    return file


def read_back(bag: Path) -> Messages:
    got: Messages = {topic: [] for topic in TOPICS}
    for topic, log_ns, data in iter_raw(bag, TOPICS):
        got[topic].append((log_ns, data))
    return got


def without(written: Messages, chunks: list[ChunkInfo], lost: int) -> Messages:
    """The messages of every chunk but ``chunks[lost]``, in order."""
    before = {t: sum(c.counts[t] for c in chunks[:lost]) for t in TOPICS}
    return {
        t: written[t][: before[t]] + written[t][before[t] + chunks[lost].counts[t] :]
        for t in TOPICS
    }


@pytest.mark.parametrize('lost', [0, 2])
def test_a_damaged_chunk_is_skipped_and_every_other_chunk_kept(
    intact: tuple[Path, Messages, list[ChunkInfo]], tmp_path: Path, lost: int
) -> None:
    """Probe A36: a flip in the first chunk recovered nothing, though the rest was intact."""
    source, written, chunks = intact
    bag = tmp_path / 'bag'
    damaged_copy(source, bag, chunks[lost])
    chunk = chunks[lost]

    report = recover_bag(bag, tmp_path / 'out')

    assert read_back(tmp_path / 'out') == without(written, chunks, lost)
    (scan,) = report.files
    (skipped,) = scan.skipped
    assert (skipped.offset, skipped.length_bytes) == (chunk.offset, chunk.length)
    assert skipped.header_ns == (chunk.first_ns, chunk.last_ns)
    assert skipped.messages_lost == sum(chunk.counts.values())
    assert report.bytes_discarded == chunk.length
    assert not scan.is_complete
    assert scan.undecoded is not None  # the original is kept for a better reader
    text = report.summary()
    assert f'damaged chunk (zstd) at byte {chunk.offset} ({chunk.length} bytes) skipped' in text
    assert f'its {sum(chunk.counts.values())} messages (log times 2026-01-01T00:00:' in text
    assert f'{chunk.length} in 1 damaged chunk(s) skipped' in text


def test_a_damaged_chunk_in_a_torn_file_keeps_the_chunks_on_both_sides(
    intact: tuple[Path, Messages, list[ChunkInfo]], tmp_path: Path
) -> None:
    """No footer, no summary: the channels declared in the first chunk still name the rest."""
    source, written, chunks = intact
    bag = tmp_path / 'bag'
    file = damaged_copy(source, bag, chunks[1])
    (bag / 'metadata.yaml').unlink()
    cut = chunks[4].offset + chunks[4].length + 20  # inside the records after chunk 4
    with file.open('r+b') as stream:
        stream.truncate(cut)

    report = recover_bag(bag)

    kept = without(
        {t: w[: sum(c.counts[t] for c in chunks[:5])] for t, w in written.items()}, chunks[:5], 1
    )
    assert read_back(bag) == kept
    (scan,) = report.files
    assert [c.offset for c in scan.skipped] == [chunks[1].offset]
    assert scan.bytes_discarded == chunks[1].length + (cut - scan.valid_bytes)
    assert scan.stop_reason is not None


def test_a_damaged_chunk_whose_length_field_is_broken_stops_the_scan_there(
    intact: tuple[Path, Messages, list[ChunkInfo]], tmp_path: Path
) -> None:
    """Where the chunk's length does not lead to a record, nothing after it can be trusted."""
    source, written, chunks = intact
    bag = tmp_path / 'bag'
    file = damaged_copy(source, bag, chunks[2])
    data = bytearray(file.read_bytes())
    length_at = chunks[2].offset + 1
    data[length_at : length_at + 8] = (chunks[2].length - 9 + 1001).to_bytes(8, 'little')
    file.write_bytes(bytes(data))

    report = recover_bag(bag, tmp_path / 'out')

    kept = {t: written[t][: sum(c.counts[t] for c in chunks[:2])] for t in TOPICS}
    assert read_back(tmp_path / 'out') == kept
    (scan,) = report.files
    assert scan.skipped == ()
    assert scan.valid_bytes == chunks[2].offset
    assert (scan.stop_reason or '').startswith(f'damaged chunk (zstd) at byte {chunks[2].offset}')
    assert 'so nothing after it is read' in (scan.stop_reason or '')


def test_messages_whose_channel_only_the_skipped_chunk_declared_are_named_when_none_is_left(
    intact: tuple[Path, Messages, list[ChunkInfo]], tmp_path: Path
) -> None:
    """A torn file has no summary to declare the channels again: their messages are lost."""
    source, _, chunks = intact
    bag = tmp_path / 'bag'
    file = damaged_copy(source, bag, chunks[0])
    (bag / 'metadata.yaml').unlink()
    with file.open('r+b') as stream:
        stream.truncate(chunks[3].offset + chunks[3].length + 20)

    with pytest.raises(BagError) as err:
        recover_bag(bag, tmp_path / 'out')
    message = str(err.value)
    assert 'no complete message could be read' in message
    assert f'damaged chunk (zstd) at byte {chunks[0].offset}' in message
    assert 'declared only in a skipped chunk' in message
    assert not (tmp_path / 'out').exists()
