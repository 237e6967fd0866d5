"""inspect reports the start and duration the messages show, and names a metadata.yaml that
disagrees with them (a starting_time edited by hand, copied from another recording)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from support import sine_recording

from id_learning.dataset.inspect import inspect_bag, render_report
from id_learning.dataset.recording import write_recording

N_SAMPLES = 50
START_NS = 1_767_225_600_000_000_000  # sine_recording's first stamp: 2026-01-01T00:00:00Z
SPAN_NS = (N_SAMPLES - 1) * 8_000_000


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path: Path = write_recording(sine_recording(N_SAMPLES), tmp_path_factory.mktemp('t') / 'bag')
    return path


def with_start(bag: Path, target: Path, start_ns: int) -> Path:
    """A copy of ``bag`` whose metadata.yaml gives another starting_time."""
    copy = Path(shutil.copytree(bag, target))
    meta = copy / 'metadata.yaml'
    text = meta.read_text(encoding='utf-8')
    old = f'nanoseconds_since_epoch: {START_NS}\n'
    assert old in text  # precondition: the writer's starting_time is the first log time
    meta.write_text(text.replace(old, f'nanoseconds_since_epoch: {start_ns}\n', 1))
    return copy


def test_a_starting_time_far_from_the_messages_is_named_and_the_messages_start_shown(
    bag: Path, tmp_path: Path
) -> None:
    """Probe A37: starting_time -5 ns was shown as the start, with no problem."""
    copy = with_start(bag, tmp_path / 'edited', -5)

    report = inspect_bag(copy)

    assert report.start_ns == START_NS
    assert report.start_iso == '2026-01-01T00:00:00.000000Z'
    assert report.duration_s == pytest.approx(SPAN_NS * 1e-9)
    assert report.metadata_mismatches == (
        'metadata: starting_time -5 ns (1969-12-31T23:59:59.999999Z), the first message is '
        f'logged at {START_NS} ns (2026-01-01T00:00:00.000000Z); start and duration above are '
        "the messages'",
    )
    text = render_report(report)
    assert f'start     2026-01-01T00:00:00.000000Z ({START_NS} ns)' in text
    assert 'starting_time -5 ns' in text
    assert 'problems  none' not in text


def test_a_starting_time_within_a_second_of_the_messages_is_no_problem(
    bag: Path, tmp_path: Path
) -> None:
    copy = with_start(bag, tmp_path / 'close', START_NS - 900_000_000)

    report = inspect_bag(copy)

    assert report.metadata_mismatches == ()
    assert report.start_ns == START_NS
