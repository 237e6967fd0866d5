"""Rebuild a bag whose writer was killed: ``metadata.yaml`` missing, ``.mcap`` files truncated.

Each ``.mcap`` file is scanned record by record with ``mcap.stream_reader.StreamReader``. A chunk
whose compressed data or CRC is damaged but whose record framing holds is skipped (named in the
report with its offset, reason and the log times lost) and the scan goes on after it; the scan
stops at the first record that is incomplete (the torn tail) or whose framing is broken.
Everything read -- schemas, channels and every message of the complete chunks -- is written again
with ``BagWriter``, message bytes and log times unchanged, so the recovered messages are what was
recorded less the torn tail and the chunks skipped. A chunk torn by the cut is not lost
whole: its compressed bytes are decompressed as a stream as far as they go (zstd, lz4 or none),
and every record complete within them is kept (the chunk's CRC cannot be checked; each record's
length is). The stop reason names the chunk (its offset and compression).

Nothing readable is ever lost, and nothing is called recovered that holds no message: a result
with no message is refused (nothing is written, in place or to ``out``), naming each file, its
size and why no message could be read from it (an empty file, a cut inside the header); and when
the scan stopped at data it could not decode (a damaged chunk, a compression it cannot stream),
in place the originals are kept as ``<file>.damaged`` whatever ``keep_damaged`` says, since a
better reader may get more.

Safety: the rebuilt bag is written to a hidden sibling folder and read back (per-topic counts must
match the scan) before anything of the original is touched. In place, the damaged files are then
renamed to ``<file>.damaged``, the new files moved in (``metadata.yaml`` last), and the damaged
files deleted unless ``keep_damaged``; when a rename fails (or is interrupted) the ones done are
undone. Files other than ``.mcap`` and ``metadata.yaml`` in the folder are left alone. A bag that
is already complete is never rewritten. The folder written (the bag in place, or ``out``) is
locked as a bag writer locks it (``outputs.output_lock``), and checked writable before the scan.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path, PurePath

import yaml
from rosbags.typesys.base import TypesysError

from id_learning.bag.messages import message_definition
from id_learning.bag.metadata_file import bag_path_problem, load_metadata, refuse_special_files
from id_learning.bag.reader import TopicInfo, bag_info
from id_learning.bag.reader_paths import folder_is_no_bag, listed_paths
from id_learning.bag.recover_scan import (
    DAMAGED_SUFFIX,
    FileScan,
    Topics,
    scan_file,
)
from id_learning.bag.writer import BagWriter
from id_learning.errors import BagError
from id_learning.outputs import check_target, os_reason, output_lock

__all__ = ['FileScan', 'RecoverReport', 'recover_bag']

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class RecoverReport:
    """What ``recover_bag`` did.

    Attributes:
        path: the bag folder that was scanned.
        output: the folder that now holds a valid bag (``path`` when in place or intact).
        is_intact: the bag was complete with valid metadata; nothing was written.
        had_metadata: ``metadata.yaml`` was present.
        files: one scan per ``.mcap`` file, in bag order.
        topics: recovered topics with their message counts, in first-seen order.
        damaged_kept: the damaged originals kept as ``<file>.damaged``.
        asked: the ``out`` asked for (None: in place); an intact bag is not copied there.
    """

    path: Path
    output: Path
    is_intact: bool
    had_metadata: bool
    files: tuple[FileScan, ...]
    topics: tuple[TopicInfo, ...]
    damaged_kept: tuple[Path, ...] = ()
    asked: Path | None = None

    @property
    def messages(self) -> int:
        """Messages recovered on all topics."""
        return sum(topic.count for topic in self.topics)

    @property
    def bytes_discarded(self) -> int:
        """Bytes lost at the files' torn tails and in the damaged chunks skipped."""
        return sum(scan.bytes_discarded for scan in self.files)

    def summary(self) -> str:
        """Describe the outcome in a few lines of plain text."""
        if self.is_intact:
            head = f'{self.path}: bag is complete with valid metadata; nothing to recover' + (
                f' (nothing written to {self.asked}: use {self.path} as it is)'
                if self.asked is not None and self.asked != self.path
                else ''
            )
        else:
            chunks = [chunk for scan in self.files for chunk in scan.skipped]
            in_chunks = sum(chunk.length_bytes for chunk in chunks)
            where = (
                f' ({self.bytes_discarded - in_chunks} at the tail, {in_chunks} in '
                f'{len(chunks)} damaged chunk(s) skipped)'
                if chunks
                else ' at the tail'
            )
            head = (
                f'{self.path}: recovered {self.messages} messages into {self.output}, '
                f'{self.bytes_discarded} bytes discarded{where}'
            )
        lines = [head]
        for scan in self.files:
            lines.append(
                f'  file {scan.name}: {scan.size_bytes} bytes, {scan.messages} messages, '
                f'{scan.bytes_discarded} bytes discarded, {scan.state()}'
            )
            lines += [f'    {chunk.describe()}' for chunk in scan.skipped]
        lines += [f'  topic {t.name} [{t.msgtype}]: {t.count} messages' for t in self.topics]
        lines += [f'  kept damaged original {path}' for path in self.damaged_kept]
        lines += [
            f'  {scan.name}: original kept: {scan.undecoded}'
            for scan in self.files
            if scan.undecoded
        ]
        return '\n'.join(lines)


def _mcap_files(path: Path) -> list[Path]:
    """The bag's ``.mcap`` files in split order (``name_2`` before ``name_10``).

    Those in the folder, and those metadata.yaml lists in its subfolders (rosbag2 resolves
    ``relative_file_paths`` against the bag folder).
    """

    def order(file: Path) -> tuple[str, int]:
        match = re.fullmatch(r'(.*?)(\d+)', file.stem)
        return (match.group(1), int(match.group(2))) if match else (file.stem, -1)

    found = [p for p in path.iterdir() if p.suffix == '.mcap' and p.is_file()]
    found += [
        file
        for entry, file in listed_paths(path)
        if PurePath(entry).parent != PurePath('.') and file.suffix == '.mcap' and file.is_file()
    ]
    return sorted(dict.fromkeys(found), key=order)


def _is_empty_folder(path: Path) -> bool:
    """Whether ``path`` is a folder with nothing in it (a recovery may fill it, as a recorder)."""
    try:
        return path.is_dir() and not any(path.iterdir())
    except OSError:
        return False


def _metadata_files(path: Path) -> set[str] | None:
    """File names ``metadata.yaml`` lists, or None when it is missing or unreadable."""
    try:
        data = load_metadata(path)
        listed = data['rosbag2_bagfile_information']['relative_file_paths']
        return {Path(str(entry)).name for entry in listed}
    except (BagError, yaml.YAMLError, KeyError, TypeError):
        return None


def _is_intact(path: Path, scans: list[FileScan], topics: Topics) -> bool:
    """Complete files, and metadata that rosbags opens and that agrees with the scan."""
    if not all(scan.is_complete for scan in scans):
        return False
    if _metadata_files(path) != {scan.name for scan in scans}:
        return False
    try:
        info = bag_info(path)
    except BagError:
        return False
    return {t.name: (t.msgtype, t.count) for t in info.topics} == {
        t.name: (t.msgtype, t.count) for t in topics.infos()
    }


def _check_types(path: Path, topics: Topics) -> None:
    """Require every type to be known to the typestore BagWriter takes definitions from."""
    for msgtype, schema_text in topics.schema_texts.items():
        names = [name for name, kind in topics.msgtypes.items() if kind == msgtype]
        try:
            text, _ = message_definition(msgtype)
        except TypesysError as err:
            raise BagError(
                f'{path}: topic(s) {names} have type {msgtype}, which the ROS 2 Jazzy typestore '
                'does not know; recovery writes standard message types only'
            ) from err
        if text.encode() != schema_text:
            _LOG.warning(
                '%s: the stored definition of %s (topics %s) differs from the Jazzy one that the '
                'recovered bag will name; message bytes are kept as they are',
                path,
                msgtype,
                names,
            )


def _write(target: Path, files: list[Path], topics: Topics) -> tuple[FileScan, ...]:
    """Write the recovered messages to a new bag folder and read its metadata back."""
    rescanned = Topics()
    with BagWriter(target) as writer:
        for name, msgtype in topics.msgtypes.items():
            writer.add_topic(name, msgtype)
        scans = tuple(scan_file(file, rescanned, writer.write) for file in files)
    expected = {t.name: t.count for t in topics.infos()}
    got = {t.name: t.count for t in bag_info(target).topics}
    if got != expected:
        raise BagError(
            f'{target}: the rebuilt bag holds {got} messages per topic, the scan found '
            f'{expected}; the original is left untouched'
        )
    return scans


def _install_in_place(
    path: Path, staged: Path, files: list[Path], keep_damaged: bool
) -> tuple[Path, ...]:
    """Swap the damaged files for the staged bag's, keeping ``metadata.yaml`` for last.

    A failed or interrupted rename undoes the renames done (the original is as it was).

    Raises:
        BagError: a rename failed (the path and the OS's reason).
    """
    old = [*files, *([path / 'metadata.yaml'] if (path / 'metadata.yaml').exists() else [])]
    damaged = [file.with_name(file.name + DAMAGED_SUFFIX) for file in old]
    clashes = [str(file) for file in damaged if file.exists()]
    if clashes:
        raise BagError(f'{path}: {clashes} already exist; move them away and recover again')
    new = sorted(staged.iterdir(), key=lambda file: file.name == 'metadata.yaml')
    done: list[tuple[Path, Path]] = []  # (from, to), in order
    try:
        for file, target in [*zip(old, damaged, strict=True), *((f, path / f.name) for f in new)]:
            file.replace(target)
            done.append((file, target))
    except BaseException as err:
        try:
            for file, target in reversed(done):
                target.replace(file)
            state = 'the original files are back in place'
        except OSError:
            state = f'the original files are kept as *{DAMAGED_SUFFIX} in {path}'
        if not isinstance(err, OSError):
            raise
        raise BagError(
            f'{err.filename2 or err.filename or path}: {os_reason(err)} (installing the '
            f'recovered bag in {path}); {state}; recover into a new folder with --out NEW_FOLDER'
        ) from err
    if keep_damaged:
        return tuple(damaged)
    for file in damaged:
        file.unlink()
    return ()


def _prepare_output(path: Path, target: Path | None, lock: contextlib.ExitStack) -> Path | None:
    """Refuse folders that cannot be written, before any work; lock the one recovered into.

    In place, the bag folder (its files are swapped) and its parent (the rebuilt bag is staged
    there) are probed; ``target`` passes ``outputs.check_target``. The lock, held until ``lock``
    closes, keeps a writer of that bag (or another recovery) out. Returns ``target``.

    Raises:
        BagError: a folder cannot be written (the OS's reason; in place, ``--out`` suggested).
        OutputError: ``target`` is refused, or another process writes the folder.
    """
    if target is not None:
        target = check_target(target, inputs=[path])
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise BagError(f'{target.parent}: {os_reason(err)} (creating the folder)') from err
    probed = ((path, 'its files are replaced'), (path.parent, 'the bag is rebuilt'))
    for folder, why in () if target else probed:
        try:
            fd, probe = tempfile.mkstemp(prefix='.id_learning-probe-', dir=folder)
        except OSError as err:
            raise BagError(
                f'{path}: cannot write in {folder} ({os_reason(err)}), where {why} when '
                'recovering in place; recover into a new folder with --out NEW_FOLDER'
            ) from err
        os.close(fd)
        os.unlink(probe)
    lock.enter_context(output_lock(target or path))
    return target


def recover_bag(
    path: Path | str,
    out: Path | str | None = None,
    *,
    keep_damaged: bool = False,
) -> RecoverReport:
    """Turn a torn rosbag2 MCAP folder into a valid bag, keeping every complete message.

    The recovered messages are a prefix of each file's messages (file order) less those of the
    damaged chunks skipped (``FileScan.skipped``), with their bytes and log times unchanged
    (publish times are set to the log times, sequence numbers renumbered).
    Split bags are merged into one ``.mcap`` file. If the bag is complete and its metadata agrees
    with its files, nothing is written, whatever ``out`` says.

    Args:
        path: the bag folder.
        out: where to write the recovered bag (a new or empty folder; the original is left
            untouched).
            None recovers in place (see the module docstring for the order of steps).
        keep_damaged: in place, keep the replaced originals as ``<file>.damaged``; otherwise they
            are deleted once the rebuilt bag has been read back, unless the scan left data it
            could not decode (``FileScan.undecoded``). Ignored with ``out``.

    Returns:
        What was scanned, recovered and discarded.

    Raises:
        BagError: path is not a folder of ``.mcap`` files, metadata.yaml or a storage file is no
            regular file (a FIFO, a device), a file is not MCAP, a type is unknown,
            no message could be read (``_refuse_empty``), ``out`` exists and is no empty folder,
            a folder to write cannot be written, or the rebuilt bag does not read back.
        OutputError: ``out`` is refused (``outputs.check_target``), or another process writes
            the folder recovered into (named by its pid).
    """
    path = Path(path)
    if (why := bag_path_problem(path)) is not None:
        raise BagError(why)
    if not path.is_dir():
        raise BagError(
            f'{path}: no such bag folder' if not path.exists() else f'{path}: not a folder'
        )
    # A FIFO or device in a bag's place is no torn recording: refused before any read or scan.
    refuse_special_files(path)
    files = _mcap_files(path)
    if not files:
        damaged = sorted(p.name for p in path.glob(f'*.mcap{DAMAGED_SUFFIX}'))
        hint = f'; only damaged originals {damaged} are left' if damaged else ''
        if not damaged and (why := folder_is_no_bag(path)) is not None:
            hint = f': {why}'
        raise BagError(f'{path}: not a rosbag2 MCAP folder (no .mcap files){hint}')
    had_metadata = (path / 'metadata.yaml').is_file()
    target = None if out is None or Path(out).resolve() == path.resolve() else Path(out)
    if target is not None and target.exists() and not _is_empty_folder(target):
        raise BagError(
            f'{target}: already exists and is not an empty folder; give a new or empty folder '
            'to recover into (nothing is ever written over)'
        )
    with contextlib.ExitStack() as lock:
        if not had_metadata:  # torn for sure: refused before the long scan, not after
            target = _prepare_output(path, target, lock)
        topics = Topics()
        scans = [scan_file(file, topics, None) for file in files]
        if had_metadata and _is_intact(path, scans, topics):
            _LOG.info('%s: bag is complete with valid metadata; nothing to recover', path)
            infos = topics.infos()
            return RecoverReport(path, path, True, had_metadata, tuple(scans), infos, asked=target)
        for scan in scans:
            for chunk in scan.skipped:
                _LOG.warning('%s: %s', path / scan.name, chunk.describe())
        _check_types(path, topics)
        _refuse_empty(path, target, scans)
        if had_metadata:
            target = _prepare_output(path, target, lock)
        # What the scan could not decode may still be read by a better reader: keep it.
        keep = keep_damaged or any(scan.undecoded for scan in scans)
        kept = _rebuild(path, target, files, tuple(scans), topics, keep_damaged=keep)
    report = RecoverReport(
        path=path,
        output=target or path,
        is_intact=False,
        had_metadata=had_metadata,
        files=tuple(scans),
        topics=topics.infos(),
        damaged_kept=kept,
    )
    _LOG.info(
        '%s: recovered %d messages on %d topics into %s, %d bytes discarded',
        path,
        report.messages,
        len(report.topics),
        report.output,
        report.bytes_discarded,
    )
    return report


def _refuse_empty(path: Path, target: Path | None, scans: list[FileScan]) -> None:
    """Refuse a result with no message, in place and into ``target`` alike.

    An empty bag recovers nothing: into a new folder it says nothing the scan did not, in place
    it would replace files whose bytes past the header might hold messages a better reader gets
    back, and from files that hold nothing (a 0-byte ``.mcap``) it would be reported as a
    recovered recording that every later command then finds without its topics.

    Raises:
        BagError: no message recovered (each file's size and why its scan stopped).
    """
    if any(scan.messages for scan in scans):
        return
    where = f'nothing written to {target}' if target is not None else 'nothing replaced'
    files = '; '.join(
        f'{scan.name} ({scan.size_bytes} bytes): '
        + (
            ', '.join([scan.state(), *(chunk.describe() for chunk in scan.skipped)])
            if scan.skipped
            else scan.stop_reason or 'no message'
        )
        for scan in scans
    )
    raise BagError(
        f'{path}: no complete message could be read ({files}); {where}, the original is left '
        'as it is'
    )


def _move_into(staged: Path, target: Path) -> None:
    """Move the staged bag to ``target``: a new folder, or an empty one it then replaces.

    The rename replaces an empty folder only (the OS refuses a non-empty one), so what was
    written into ``target`` meanwhile is never overwritten.

    Raises:
        BagError: the rename failed (the OS's reason); nothing was written to ``target``.
    """
    try:
        staged.replace(target)
    except OSError as err:
        raise BagError(
            f'{target}: {os_reason(err)} (moving the recovered bag there: it must be absent or '
            'an empty folder); nothing was written to it, the original is left as it is'
        ) from err


def _rebuild(
    path: Path,
    target: Path | None,
    files: list[Path],
    scans: tuple[FileScan, ...],
    topics: Topics,
    *,
    keep_damaged: bool,
) -> tuple[Path, ...]:
    """Write the recovered bag beside its destination, then move it there; the kept originals."""
    # A hidden sibling: same file system (renames are atomic), and the bag inside keeps the
    # final folder's name, which BagWriter uses for the .mcap file names.
    parent = (target or path).parent
    name = (target or path).name
    staging_root = parent / f'.{name}.recovering'
    if staging_root.exists():
        shutil.rmtree(staging_root)  # left by an interrupted recovery; ours by its name
    staging_root.mkdir(parents=True)
    try:
        staged = staging_root / name
        try:
            written = _write(staged, files, topics)
        except BagError as err:  # the writer's words name the hidden folder, removed below
            found = re.search(r'writing failed: (.+?)(?:;| \(|$)', str(err))
            raise BagError(
                f'{target or path}: the recovered bag could not be written '
                f'({found.group(1) if found else err}): nothing was written there, and {path} '
                'is as it was; free space (or choose another --out) and recover again'
            ) from err
        if written != scans:
            raise BagError(f'{path}: the files changed while being recovered; try again')
        if target is not None:
            _move_into(staged, target)
            kept: tuple[Path, ...] = ()
        else:
            kept = _install_in_place(path, staged, files, keep_damaged)
    finally:
        shutil.rmtree(staging_root, ignore_errors=True)
    return kept
