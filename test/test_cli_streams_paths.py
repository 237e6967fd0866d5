"""Probe 7 A, B, F, H: '.' as an output, unwritable standard streams, hyper-file kinds, demo."""

from __future__ import annotations

import io
import os
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from id_learning.cli.main import main
from id_learning.cli.streams import Guarded, failure
from id_learning.outputs import named_path, partial_path


@given(st.lists(st.sampled_from(['.', '..', 'a', 'b']), min_size=0, max_size=5))
def test_named_path_always_has_a_name(parts: list[str]) -> None:
    path = Path('/nonexistent/a/b/c/d/e/f', *parts)  # deep enough: '..' never reaches '/'
    named = named_path(path)
    assert named.name not in ('', '.', '..')
    assert os.path.realpath(named) == os.path.realpath(path)
    assert partial_path(path).parent.resolve() == named.parent.resolve()


class _Full(io.StringIO):
    def write(self, text: str) -> int:
        raise OSError(28, 'No space left on device')


def test_guarded_notes_the_first_failure() -> None:
    closed = Guarded(None)
    closed.write('x')
    assert failure('output', closed) == 'cannot write the standard output: it is closed'
    full = Guarded(_Full())
    full.write('x')
    full.write('y')
    assert failure('output', full) == 'cannot write the standard output: No space left on device'
    assert failure('output', Guarded(io.StringIO())) is None


def test_a_stream_in_ascii_gets_escapes_not_a_write_failure() -> None:
    # Probe 15 (A97): PYTHONIOENCODING=ascii and a robot named with a non-ASCII letter made
    # inspect print nothing and say "cannot write the standard output: Bad file descriptor".
    buffer = io.BytesIO()
    ascii_out = Guarded(io.TextIOWrapper(buffer, encoding='ascii', write_through=True))
    ascii_out.write('robot Roboter-Kühn: 6 joints\n')
    assert failure('output', ascii_out) is None
    assert buffer.getvalue() == b'robot Roboter-K\\xfchn: 6 joints\n'


def test_version_on_a_full_stdout_is_one_line_and_1(monkeypatch: pytest.MonkeyPatch) -> None:
    err = io.StringIO()
    monkeypatch.setattr('sys.stdout', _Full())
    monkeypatch.setattr('sys.stderr', err)
    assert main(['--version']) == 1
    assert err.getvalue() == (
        'id-learning: error: cannot write the standard output: No space left on device\n'
    )


def test_demo_refuses_models_with_skip_training(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ['demo', '--skip-training', '--skip-diagnosis', '--models', 'mlp', '--out', 'x']
    assert main(argv) == 2
    assert '--models means nothing with --skip-training' in capsys.readouterr().err


def test_hyper_file_unknown_kind(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from id_learning.errors import ConfigError
    from id_learning.training.fitting import resolve_overrides

    with pytest.raises(ConfigError, match=r"unknown model kind\(s\) \['transformer'\]; known"):
        resolve_overrides(['mlp'], {'transformer': {}}, max_seconds=None, device='cpu')
    with pytest.raises(ConfigError, match='kinds that are not trained'):
        resolve_overrides(['mlp'], {'lstm': {}}, max_seconds=None, device='cpu')


TWIN = str(Path(__file__).resolve().parents[1] / 'config' / 'twin_default.yaml')


def test_simulate_writes_into_an_empty_current_folder_and_refuses_a_full_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    here = tmp_path / 'here'
    here.mkdir()
    monkeypatch.chdir(here)
    assert main(['simulate', '--config', TWIN, '--out', '.', '--duration', '1', '--quiet']) == 0
    assert (here / 'metadata.yaml').is_file()
    full = tmp_path / 'full'
    full.mkdir()
    (full / 'keep.txt').write_text('mine')
    monkeypatch.chdir(full)
    capsys.readouterr()
    assert main(['simulate', '--config', TWIN, '--out', '.', '--duration', '1', '--quiet']) == 2
    said = capsys.readouterr().err
    assert 'keep.txt' in said
    assert 'Traceback' not in said
    assert sorted(p.name for p in full.iterdir()) == ['keep.txt']


def test_bag_recover_in_place_from_inside_the_torn_bag(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from support import sine_recording

    from id_learning.bag import bag_info
    from id_learning.dataset.recording import write_recording

    bag = write_recording(sine_recording(50), tmp_path / 'torn')
    (bag / 'metadata.yaml').unlink()
    monkeypatch.chdir(bag)
    assert main(['bag', 'recover', '.']) == 0
    assert bag_info(bag).topic('/joint_states').count == 50


@given(value=st.one_of(st.integers(-5, 2_000_000), st.just(True), st.floats(0.5, 3.0)))
def test_stale_after_cycles_takes_the_integers_the_core_can_count(value: object) -> None:
    from id_learning.errors import ConfigError
    from id_learning.predictor import GuardConfig

    valid = isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 10**6
    if valid:
        assert GuardConfig(stale_after_cycles=value).stale_after_ns == round(value * 0.008e9)  # type: ignore[arg-type]
    else:
        with pytest.raises(ConfigError, match=r'stale_after_cycles must be an integer in \[1, '):
            GuardConfig(stale_after_cycles=value)  # type: ignore[arg-type]
