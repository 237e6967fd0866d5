"""recover_bag on lz4 and zstd chunked MCAP files cut anywhere: nothing readable is lost.

The files are written by the mcap library (the compressions other recorders use). What a cut
file holds is computed apart from ``recover``: the messages of the chunks complete before the
cut, plus those of the cut chunk whose records end within what the compression's own stream
decoder gives back from its bytes.
"""

from __future__ import annotations

import struct
import tempfile
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from id_learning.bag import JOINT_STATE, encode_joint_state, iter_raw
from id_learning.bag.messages import message_definition
from id_learning.bag.recover import recover_bag
from id_learning.errors import BagError

TOPIC = '/joint_states'
JOINTS = ('joint_1', 'joint_2', 'joint_3')
N_MESSAGES = 600
T0_NS = 1_700_000_000 * 1_000_000_000
COMPRESSIONS = {'lz4': CompressionType.LZ4, 'zstd': CompressionType.ZSTD}
Written = list[tuple[int, bytes]]


def write_mcap(path: Path, compression: str, chunk_bytes: int) -> Written:
    """A one-topic ros2 MCAP file in chunks of the given compression; (log time, bytes) each."""
    rng = np.random.default_rng(3)
    written: Written = []
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open('wb') as stream:
        writer = Writer(stream, chunk_size=chunk_bytes, compression=COMPRESSIONS[compression])
        writer.start(profile='ros2', library='test')
        text, _ = message_definition(JOINT_STATE)
        schema = writer.register_schema(JOINT_STATE, 'ros2msg', text.encode())
        channel = writer.register_channel(TOPIC, 'cdr', schema)
        for k in range(N_MESSAGES):
            log_ns = T0_NS + k * 8_000_000
            q, v, e = rng.normal(size=(3, len(JOINTS)))
            data = encode_joint_state(log_ns, JOINTS, q, v, e)
            writer.add_message(channel, log_ns, data, log_ns)
            written.append((log_ns, data))
        writer.finish()
    return written


def _stream_decode(compression: str, compressed: bytes) -> bytes:
    """What the compression's own stream decoder gives back from a cut stream."""
    if compression == 'lz4':
        return bytes(lz4.frame.LZ4FrameDecompressor().decompress(compressed))
    return bytes(zstandard.ZstdDecompressor().decompressobj().decompress(compressed))


def _message_ends(records: bytes) -> list[int]:
    """End offsets of the message records in a chunk's uncompressed records."""
    ends, at = [], 0
    while at < len(records):
        opcode, length = records[at], struct.unpack_from('<Q', records, at + 1)[0]
        at += 9 + length
        if opcode == 0x05:  # Message
            ends.append(at)
    return ends


def readable_before(file: Path, compression: str, cut: int) -> int:
    """Messages a file cut at byte ``cut`` still holds, from the intact file's chunk index."""
    with file.open('rb') as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None
        raw = file.read_bytes()
    count = 0
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        start, end = index.chunk_start_offset, index.chunk_start_offset + index.chunk_length
        if start >= cut:
            break
        # opcode, length, start/end time, uncompressed size, CRC, compression name, data length
        name_at = start + 1 + 8 + 8 + 8 + 8 + 4
        (name_length,) = struct.unpack_from('<I', raw, name_at)
        data_at = name_at + 4 + name_length + 8
        full = _stream_decode(compression, raw[data_at:end])
        ends = _message_ends(full)
        if end <= cut:
            count += len(ends)
        else:
            got = len(_stream_decode(compression, raw[data_at:cut])) if cut > data_at else 0
            count += sum(1 for at in ends if at <= got)
    return count


class Intact(dict[str, tuple[Path, Written]]):
    """Per compression (the intact file, what it holds); short in hypothesis's reports."""

    def __repr__(self) -> str:
        return f'Intact({sorted(self)})'


@pytest.fixture(scope='module')
def intact(tmp_path_factory: pytest.TempPathFactory) -> Intact:
    """Per compression an intact file in ~100 kB chunks (two lz4 blocks of 64 KiB each)."""
    root = tmp_path_factory.mktemp('compressed')
    files = Intact()
    for name in COMPRESSIONS:
        file = root / name / f'{name}_0.mcap'
        files[name] = (file, write_mcap(file, name, chunk_bytes=100_000))
    return files


def cut_copy(file: Path, bag: Path, cut: int) -> Path:
    """A bag folder as a killed writer leaves it: no metadata.yaml, its one file cut at ``cut``."""
    bag.mkdir(parents=True)
    torn = bag / file.name
    torn.write_bytes(file.read_bytes()[:cut])
    return torn


def read_back(bag: Path) -> Written:
    return [(log_ns, data) for _, log_ns, data in iter_raw(bag, [TOPIC])]


@pytest.mark.parametrize('compression', sorted(COMPRESSIONS))
@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(share=st.floats(min_value=0.0, max_value=1.0))
def test_a_cut_file_gives_back_exactly_the_messages_it_still_holds_and_loses_nothing(
    intact: Intact, compression: str, share: float
) -> None:
    file, written = intact[compression]
    cut = int(file.stat().st_size * share)
    expected = readable_before(file, compression, cut)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / 'bag'
        torn = cut_copy(file, bag, cut)
        original = torn.read_bytes()
        if expected == 0:
            out = Path(tmp) / 'out'
            with pytest.raises(BagError, match='no complete message could be read'):
                recover_bag(bag, out)  # never an empty bag into a new folder
            assert not out.exists()
            with pytest.raises(BagError, match='nothing replaced'):
                recover_bag(bag)  # in place too, an empty file as well
            assert torn.read_bytes() == original
            return
        report = recover_bag(bag)
        assert read_back(bag) == written[:expected]  # exactly: bytes and log times
        assert report.messages == expected
        (scan,) = report.files
        assert scan.undecoded is None  # a plain cut: all that is readable was read


def test_a_single_lz4_chunk_cut_in_half_keeps_its_complete_messages(tmp_path: Path) -> None:
    """The probe's case: one lz4 chunk holds most of the file, the cut goes through it."""
    file = tmp_path / 'one' / 'one_0.mcap'
    written = write_mcap(file, 'lz4', chunk_bytes=1 << 24)
    bag = tmp_path / 'bag'
    cut_copy(file, bag, int(file.stat().st_size * 0.55))

    report = recover_bag(bag)

    got = read_back(bag)
    assert 0.4 * N_MESSAGES <= len(got) < N_MESSAGES
    assert got == written[: len(got)]
    assert 'lz4 chunk at byte' in (report.files[0].stop_reason or '')


def test_a_cut_before_the_first_message_is_refused_into_out_and_writes_nothing(
    intact: Intact, tmp_path: Path
) -> None:
    file, _ = intact['lz4']
    bag = tmp_path / 'bag'
    cut_copy(file, bag, 200)  # inside the first chunk's header
    with pytest.raises(BagError, match=r'no complete message.*nothing written to .*out'):
        recover_bag(bag, tmp_path / 'out')
    assert not (tmp_path / 'out').exists()


def test_an_empty_file_recovered_into_out_is_refused(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'bag_0.mcap').write_bytes(b'')
    with pytest.raises(BagError, match=r'no complete message.*nothing written'):
        recover_bag(bag, tmp_path / 'out')
    assert not (tmp_path / 'out').exists()


def test_a_cut_chunk_this_reader_cannot_decode_keeps_the_original_beside(
    intact: Intact, tmp_path: Path
) -> None:
    """A compression without a stream decoder here: the complete chunks are recovered, and the
    original stays as ``.damaged`` (a better reader may get the rest), keep_damaged or not."""
    file, written = intact['zstd']
    with file.open('rb') as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None
    last = max(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    bag = tmp_path / 'bag'
    torn = cut_copy(file, bag, last.chunk_start_offset + last.chunk_length // 2)
    data = bytearray(torn.read_bytes())
    name_at = last.chunk_start_offset + 1 + 8 * 4 + 4 + 4
    assert data[name_at : name_at + 4] == b'zstd'
    data[name_at : name_at + 4] = b'zzzz'  # a compression unknown here
    torn.write_bytes(bytes(data))

    report = recover_bag(bag)

    expected = readable_before(file, 'zstd', last.chunk_start_offset)
    assert read_back(bag) == written[:expected]
    (scan,) = report.files
    assert scan.undecoded is not None
    assert "'zzzz'" in scan.undecoded
    kept = bag / f'{torn.name}.damaged'
    assert report.damaged_kept == (kept,)
    assert kept.read_bytes() == bytes(data)
    assert 'original kept' in report.summary()
