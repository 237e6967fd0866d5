"""recover_bag on bags torn the way a killed writer leaves them, built in code."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import MessageIndex

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, iter_raw, read_joint_states
from id_learning.bag.recover import recover_bag
from id_learning.errors import BagError

TOPICS = ('/joint_states', '/motor_currents')
JOINTS = ('joint_1', 'joint_2', 'joint_3')
N_SAMPLES = 2000
PERIOD_NS = 8_000_000
T0_NS = 1_700_000_000 * 1_000_000_000

Messages = dict[str, list[tuple[int, bytes]]]


def write_bag(path: Path, chunk_bytes: int = 4096) -> Messages:
    """A two-topic bag in small chunks; returns each topic's (log time, bytes) in write order."""
    rng = np.random.default_rng(7)
    empty = np.zeros(0)
    written: Messages = {topic: [] for topic in TOPICS}
    with BagWriter(path, chunk_bytes=chunk_bytes) as writer:
        for topic in TOPICS:
            writer.add_topic(topic, JOINT_STATE)
        for k in range(N_SAMPLES):
            stamp = T0_NS + k * PERIOD_NS
            q, v, i = rng.normal(size=(3, len(JOINTS)))
            for topic, data in (
                (TOPICS[0], encode_joint_state(stamp, JOINTS, q, v, empty)),
                (TOPICS[1], encode_joint_state(stamp, JOINTS, empty, empty, i)),
            ):
                log_ns = stamp + 1000 * (topic == TOPICS[1])  # log times unlike header stamps
                writer.write(topic, log_ns, data)
                written[topic].append((log_ns, data))
    return written


@pytest.fixture(scope='module')
def intact_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Messages]:
    path = tmp_path_factory.mktemp('intact') / 'bag'
    return path, write_bag(path)


def mcap_file(bag: Path) -> Path:
    (file,) = bag.glob('*.mcap')
    return file


def complete_chunk_messages(file: Path, cut: int) -> tuple[int, int]:
    """(messages in chunks that end at or before byte cut, end offset of the last such chunk).

    Read from the intact file's summary: chunk offsets from its chunk indexes, message counts
    from the message index records they point to.
    """
    with file.open('rb') as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None
        messages, end = 0, 0
        for chunk in summary.chunk_indexes:
            chunk_end = chunk.chunk_start_offset + chunk.chunk_length
            if chunk_end > cut:
                continue
            end = max(end, chunk_end)
            for offset in chunk.message_index_offsets.values():
                stream.seek(offset + 9)  # opcode (1) and record length (8)
                messages += len(MessageIndex.read(ReadDataStream(stream)).records)
    return messages, end


def torn_copy(source: Path, target: Path, fraction: float) -> int:
    """Copy a bag as a killed writer leaves it: no metadata.yaml, the file cut; returns the cut."""
    shutil.copytree(source, target)
    (target / 'metadata.yaml').unlink()
    file = mcap_file(target)
    cut = int(file.stat().st_size * fraction)
    with file.open('r+b') as stream:
        stream.truncate(cut)
    return cut


def read_back(bag: Path) -> Messages:
    got: Messages = {topic: [] for topic in TOPICS}
    for topic, log_ns, data in iter_raw(bag, TOPICS):
        got[topic].append((log_ns, data))
    return got


@pytest.mark.parametrize('fraction', [0.3, 0.7])
def test_torn_bag_recovers_a_bit_exact_prefix_with_every_complete_chunk(
    intact_bag: tuple[Path, Messages], tmp_path: Path, fraction: float
) -> None:
    source, written = intact_bag
    bag = tmp_path / 'bag'
    cut = torn_copy(source, bag, fraction)
    expected_at_least, last_chunk_end = complete_chunk_messages(mcap_file(source), cut)
    assert expected_at_least > 0  # precondition: the cut keeps some complete chunks

    report = recover_bag(bag)

    got = read_back(bag)
    total = sum(len(messages) for messages in got.values())
    assert total >= expected_at_least
    assert total < 2 * N_SAMPLES
    for topic in TOPICS:
        assert got[topic] == written[topic][: len(got[topic])]  # prefix: bytes and log times
    assert {t.name: t.count for t in report.topics} == {t: len(got[t]) for t in TOPICS}
    assert not report.is_intact
    assert not report.had_metadata
    (scan,) = report.files
    assert scan.size_bytes == cut
    assert not scan.is_complete
    assert scan.valid_bytes + scan.bytes_discarded == cut
    assert 0 < scan.bytes_discarded <= cut - last_chunk_end
    states = read_joint_states(bag, TOPICS[0])
    assert states.names == JOINTS
    assert len(states.stamps_ns) == len(got[TOPICS[0]])
    assert [p.name for p in sorted(bag.iterdir())] == ['bag_0.mcap', 'metadata.yaml']


def test_a_chunk_torn_by_the_cut_keeps_its_complete_messages(tmp_path: Path) -> None:
    """One chunk holds the whole recording (as an offline writer's large chunks can): cut in
    half, it still gives back about half of the messages, a bit-exact prefix."""
    source = tmp_path / 'one_chunk'
    written = write_bag(source, chunk_bytes=1 << 24)
    bag = tmp_path / 'bag'
    cut = torn_copy(source, bag, 0.5)
    assert complete_chunk_messages(mcap_file(source), cut)[0] == 0  # no complete chunk

    report = recover_bag(bag)

    got = read_back(bag)
    total = sum(len(messages) for messages in got.values())
    assert 0.4 * 2 * N_SAMPLES <= total < 2 * N_SAMPLES
    for topic in TOPICS:
        assert got[topic] == written[topic][: len(got[topic])]
    (scan,) = report.files
    assert scan.messages == total
    assert 'messages kept from its complete part' in (scan.stop_reason or '')


def test_a_zero_byte_file_is_refused_and_nothing_is_written(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    """Probe RC6: a recording with no message is no recovered bag, in place or into --out."""
    bag = tmp_path / 'bag'
    assert torn_copy(intact_bag[0], bag, 0.0) == 0
    before = sorted(p.name for p in bag.iterdir())

    with pytest.raises(BagError) as err:
        recover_bag(bag)
    assert str(err.value) == (
        f'{bag}: no complete message could be read (bag_0.mcap (0 bytes): empty file); nothing '
        'replaced, the original is left as it is'
    )
    assert sorted(p.name for p in bag.iterdir()) == before
    assert not (bag / 'metadata.yaml').exists()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith('.')) == []


def test_an_empty_file_beside_its_metadata_is_refused_and_left_as_it_is(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    bag = tmp_path / 'bag'
    shutil.copytree(intact_bag[0], bag)
    mcap_file(bag).write_bytes(b'')
    before = {p.name: p.read_bytes() for p in bag.iterdir()}

    for out in (None, tmp_path / 'out'):
        with pytest.raises(BagError, match=r'bag_0\.mcap \(0 bytes\): empty file\); nothing'):
            recover_bag(bag, out)
    assert {p.name: p.read_bytes() for p in bag.iterdir()} == before
    assert not (tmp_path / 'out').exists()


def test_complete_file_without_metadata_recovers_every_message(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    source, written = intact_bag
    bag = tmp_path / 'bag'
    torn_copy(source, bag, 1.0)

    report = recover_bag(bag)

    assert report.files[0].is_complete
    assert report.bytes_discarded == 0
    assert read_back(bag) == written


def test_keep_damaged_keeps_the_original_bytes_beside_the_recovered_bag(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    bag = tmp_path / 'bag'
    torn_copy(intact_bag[0], bag, 0.5)
    original = mcap_file(bag).read_bytes()

    report = recover_bag(bag, keep_damaged=True)

    damaged = bag / 'bag_0.mcap.damaged'
    assert report.damaged_kept == (damaged,)
    assert damaged.read_bytes() == original
    assert report.messages > 0


def test_recovering_into_out_leaves_the_torn_bag_untouched(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    bag = tmp_path / 'torn'
    torn_copy(intact_bag[0], bag, 0.5)
    before = {p.name: p.read_bytes() for p in bag.iterdir()}

    report = recover_bag(bag, tmp_path / 'fixed')

    assert {p.name: p.read_bytes() for p in bag.iterdir()} == before
    assert report.output == tmp_path / 'fixed'
    assert sum(len(m) for m in read_back(tmp_path / 'fixed').values()) == report.messages
    assert not (tmp_path / '.fixed.recovering').exists()


def test_recovering_an_intact_bag_changes_nothing(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    bag = tmp_path / 'bag'
    shutil.copytree(intact_bag[0], bag)
    before = {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in bag.iterdir()}

    report = recover_bag(bag)

    assert report.is_intact
    assert 'nothing to recover' in report.summary()
    assert 'nothing written to' not in report.summary()
    assert report.messages == 2 * N_SAMPLES
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in bag.iterdir()} == before
    # Probe 16 (C53): with --out, the summary says nothing went there and the bag is to be used.
    elsewhere = recover_bag(bag, tmp_path / 'copy')
    assert f'(nothing written to {tmp_path / "copy"}: use {bag} as it is)' in elsewhere.summary()
    assert not (tmp_path / 'copy').exists()


def test_folder_without_mcap_files_raises_bag_error(tmp_path: Path) -> None:
    (tmp_path / 'notes.txt').write_text('not a bag', encoding='utf-8')
    with pytest.raises(BagError, match=r'not a rosbag2 MCAP folder \(no \.mcap files\)'):
        recover_bag(tmp_path)


def test_file_that_is_not_mcap_raises_bag_error(tmp_path: Path) -> None:
    (tmp_path / 'bag_0.mcap').write_bytes(b'SQLite format 3\x00')
    with pytest.raises(BagError, match='not an MCAP file'):
        recover_bag(tmp_path)


def test_missing_folder_raises_bag_error(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='no such bag folder'):
        recover_bag(tmp_path / 'nowhere')


def test_zero_filled_tail_stops_at_the_first_damaged_chunk(
    intact_bag: tuple[Path, Messages], tmp_path: Path
) -> None:
    # After a power loss a file system may keep the file's length but not its last blocks.
    source, written = intact_bag
    bag = tmp_path / 'bag'
    cut = torn_copy(source, bag, 1.0)
    cut = int(cut * 0.6)
    file = mcap_file(bag)
    size = file.stat().st_size
    with file.open('r+b') as stream:
        stream.seek(cut)
        stream.write(bytes(size - cut))
    expected_at_least, _ = complete_chunk_messages(mcap_file(source), cut)
    assert expected_at_least > 0

    report = recover_bag(bag)

    got = read_back(bag)
    assert sum(len(messages) for messages in got.values()) >= expected_at_least
    for topic in TOPICS:
        assert got[topic] == written[topic][: len(got[topic])]
    assert report.files[0].stop_reason is not None
    assert report.files[0].stop_reason.startswith('damaged chunk')
