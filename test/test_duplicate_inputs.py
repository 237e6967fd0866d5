"""Inputs given twice, empty selections, extra CSV cells, unlisted bag files, wrong robots."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import pytest

from id_learning.bag.distinct import check_distinct
from id_learning.bag.reader import bag_info
from id_learning.cli import options
from id_learning.dataset.import_mapping import ColumnSpec, ImportMapping, JointColumns
from id_learning.dataset.importer import import_logs
from id_learning.errors import ConfigError, DatasetError


def _csv(path: Path, n: int = 50, extra_at: int | None = None) -> Path:
    rows = [f'{8.0 * k},{0.01 * k},{0.02 * k}' for k in range(n)]
    if extra_at is not None:
        rows[extra_at] += ',9.5,7'
    path.write_text('t,q1,v1\n' + '\n'.join(rows) + '\n', encoding='utf-8')
    return path


def _mapping() -> ImportMapping:
    joint = JointColumns(
        name='joint_1', position=ColumnSpec('q1', 'rad'), velocity=ColumnSpec('v1', 'rad/s')
    )
    return ImportMapping(joints=(joint,), time=ColumnSpec('t', 'ms'))


# -- given twice ----------------------------------------------------------------------------------
def test_the_same_path_twice_is_refused_naming_both_spellings(tmp_path: Path) -> None:
    log = _csv(tmp_path / 'a.csv')
    with pytest.raises(ConfigError, match=r'--bag: .*a\.csv is given twice'):
        check_distinct([log, tmp_path / '.' / 'a.csv'], '--bag')


def test_a_copy_with_identical_bytes_is_refused_and_distinct_inputs_pass(tmp_path: Path) -> None:
    a = _csv(tmp_path / 'a.csv')
    b = tmp_path / 'b.csv'
    shutil.copy(a, b)
    with pytest.raises(ConfigError, match=r'b\.csv holds the same data as .*a\.csv'):
        check_distinct([a, b], 'import')
    c = _csv(tmp_path / 'c.csv', n=49)
    assert check_distinct([a, c], 'import') == [a, c]


def test_a_bag_folder_and_its_copy_are_refused_by_bag_paths(
    short_bag: Path, tmp_path: Path
) -> None:
    copy = tmp_path / 'copy'
    shutil.copytree(short_bag, copy)
    with pytest.raises(ConfigError, match=r'--bag: .*copy holds the same data'):
        options.bag_paths([str(short_bag), str(copy)])
    with pytest.raises(ConfigError, match='given twice'):
        options.bag_paths([str(short_bag), str(short_bag)])


def test_import_of_one_log_twice_is_refused(tmp_path: Path) -> None:
    log = _csv(tmp_path / 'a.csv')
    with pytest.raises(ConfigError, match=r'import: .*a\.csv is given twice'):
        import_logs([log, log], _mapping(), tmp_path / 'bag')
    with pytest.raises(ConfigError, match='given twice'):  # a folder and a file in it
        import_logs([tmp_path, log], _mapping(), tmp_path / 'bag2')
    assert not (tmp_path / 'bag').exists()


# -- extra cells ----------------------------------------------------------------------------------
def test_a_row_with_extra_cells_is_refused_naming_file_line_and_cell_count(tmp_path: Path) -> None:
    log = _csv(tmp_path / 'log.csv', extra_at=4)
    with pytest.raises(DatasetError, match=r'log\.csv: line 6 has 5 cells, 2 more than the 3'):
        import_logs([log], _mapping(), tmp_path / 'bag')


def test_trailing_empty_cells_are_no_extra_data(tmp_path: Path) -> None:
    log = tmp_path / 'log.csv'
    log.write_text(
        't,q1,v1\n' + '\n'.join(f'{8.0 * k},{0.01 * k},{0.02 * k},' for k in range(50)) + '\n'
    )
    reports = import_logs([log], _mapping(), tmp_path / 'bag')
    assert reports[0].n_rows_written == 50


# -- empty selections -----------------------------------------------------------------------------
@pytest.mark.parametrize('text', ['', ',', ' , '])
def test_an_empty_effects_list_is_refused(text: str) -> None:
    with pytest.raises(ConfigError, match=r'--effects .* names no effect'):
        options.effect_names(text)
    assert options.effect_names(None) is None
    assert options.effect_names('cogging, payload_mass') == ['cogging', 'payload_mass']


def test_an_empty_effects_tuple_is_refused_by_the_diagnosis_config() -> None:
    from id_learning.diagnosis import DiagnosisConfig

    with pytest.raises(ConfigError, match=r'diagnosis\.effects: empty'):
        DiagnosisConfig(effects=())


# -- bags -----------------------------------------------------------------------------------------
@pytest.fixture(scope='module')
def short_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny contract bag of a 2-joint recording."""
    out = tmp_path_factory.mktemp('bags')
    log = _csv(out / 'log.csv', n=200)
    import_logs([log], _mapping(), out / 'bag')
    return out / 'bag'


def test_an_unlisted_storage_file_is_warned_about_once(
    short_bag: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bag = tmp_path / 'bag'
    shutil.copytree(short_bag, bag)
    shutil.copy(next(bag.glob('*.mcap')), bag / 'bag_1.mcap')
    with caplog.at_level(logging.WARNING, logger='id_learning.bag.reader'):
        bag_info(bag)
        bag_info(bag)
    warned = [r.getMessage() for r in caplog.records if 'bag_1.mcap' in r.getMessage()]
    assert len(warned) == 1
    assert 'not listed in metadata.yaml' in warned[0]


def test_inspect_reports_joints_that_are_not_the_robots_as_a_problem(
    short_twin_bag: Path, robot_configs: dict[str, object]
) -> None:
    from id_learning.dataset.inspect import inspect_bag

    report = inspect_bag(short_twin_bag, robot=robot_configs['ur5'])  # type: ignore[arg-type]
    mismatch = [line for line in report.problems if 'joints do not match ur5' in line.lower()]
    assert mismatch
    assert 'limits were not checked' in mismatch[0]
    assert not [
        line
        for line in inspect_bag(short_twin_bag, robot=robot_configs['mabi_max100']).problems  # type: ignore[arg-type]
        if 'do not match' in line
    ]


@pytest.fixture(scope='module')
def short_twin_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 26 s default twin bag of the MABI arm."""
    from support import twin_config

    from id_learning.twin import simulate, write_twin_output

    config = twin_config(26.0)
    out = tmp_path_factory.mktemp('twin') / 'bag'
    return write_twin_output(simulate(config), config, out)


# -- sweep storage --------------------------------------------------------------------------------
def test_a_sqlite_storage_in_a_missing_folder_is_refused_at_once(tmp_path: Path) -> None:
    from id_learning.training.sweep_storage import check_sqlite_file

    with pytest.raises(ConfigError, match=r'folder /no/such/dir does not exist'):
        check_sqlite_file('sqlite:////no/such/dir/x.db')
    check_sqlite_file(f'sqlite:///{tmp_path / "x.db"}')
    check_sqlite_file('postgresql://host/db')
