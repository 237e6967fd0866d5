"""Hyper-parameter sweeps on Optuna: shared studies, pruning, best.yaml into train, failures."""

from __future__ import annotations

import os
import pwd
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import optuna
import pytest
import yaml
from support import twin_config

from id_learning.cli.main import main as cli
from id_learning.dataset.preprocess import prepare_dataset
from id_learning.dataset.recording import load_recording
from id_learning.errors import ConfigError
from id_learning.models.data import TrainingData
from id_learning.models.registry import make_model
from id_learning.training.sweep import (
    SEARCH_SPACES,
    lost_schema_race,
    run_sweep,
    validation_error,
)
from id_learning.twin import simulate, write_twin_output

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    config = twin_config(60.0, seed=13)
    return write_twin_output(simulate(config), config, tmp_path_factory.mktemp('sweep') / 'bag')


def _worker(bag: Path, out: Path, storage: str, trials: int, seed: int) -> subprocess.Popen:
    code = 'import sys; from id_learning.cli.main import main; sys.exit(main(sys.argv[1:]))'
    command = [
        sys.executable, '-c', code, 'sweep', '--bag', str(bag), '--model', 'rnea_lq',
        '--trials', str(trials), '--storage', storage, '--study-name', 'shared',
        '--out', str(out), '--seed', str(seed), '--quiet',
    ]  # fmt: skip
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def _finish(workers: list[subprocess.Popen], timeout: float = 240.0) -> None:
    try:
        for worker in workers:
            output, _ = worker.communicate(timeout=timeout)
            assert worker.returncode == 0, output.decode(errors='replace')
    finally:
        for worker in workers:
            if worker.poll() is None:
                worker.kill()
                worker.wait()


def _complete(storage: str, name: str = 'shared') -> list[optuna.trial.FrozenTrial]:
    study = optuna.load_study(study_name=name, storage=storage)
    return study.get_trials(states=(optuna.trial.TrialState.COMPLETE,))


def test_two_workers_on_one_sqlite_storage_leave_four_trials_in_one_study(bag, tmp_path):
    storage = f'sqlite:///{tmp_path / "shared.db"}'
    workers = [_worker(bag, tmp_path / f'w{k}', storage, 2, seed=k) for k in range(2)]
    _finish(workers)
    trials = _complete(storage)
    assert len(trials) == 4
    best = min(trials, key=lambda t: t.value)
    for k in range(2):
        # Each worker writes the study's best so far; the later one sees all four trials.
        params = yaml.safe_load((tmp_path / f'w{k}' / 'best.yaml').read_text())['rnea_lq']
        assert params['friction'] in SEARCH_SPACES['rnea_lq']['friction'][1]
    assert {t.params['friction'] for t in trials} <= set(SEARCH_SPACES['rnea_lq']['friction'][1])
    assert best.value == pytest.approx(min(t.value for t in trials))


def test_the_objective_is_the_validation_error_and_best_yaml_trains(bag, tmp_path, mabi):
    folder = tmp_path / 'sweep'
    result = run_sweep([bag], mabi, 'motor', 'rnea_lq', folder, trials=3, progress=False, seed=0)
    assert result.finished == 3
    assert result.storage == f'sqlite:///{(folder / "sweep.db").resolve()}'
    assert {p.name for p in result.figures} == {
        'optimisation_history.png',
        'parameter_importances.png',
    }
    # The objective, recomputed independently of the sweep: fit the best settings and score
    # the validation tail (the test part never enters).
    dataset = prepare_dataset(load_recording(bag, mabi), mabi)
    data = TrainingData(dataset, mabi)
    model = make_model('rnea_lq', mabi, **result.best_params).fit(data)
    assert validation_error(model, data) == pytest.approx(result.best_value, rel=1e-9)
    # train --hyper-file takes best.yaml; --hyper items override it (beside the sweep: nothing
    # is written into another command's result).
    out = tmp_path / 'run'
    code = cli([
        'train', '--bag', str(bag), '--models', 'rnea_lq', '--out', str(out), '--quiet',
        '--hyper-file', str(result.best_file),
    ])  # fmt: skip
    assert code == 0
    saved = yaml.safe_load((out / 'models' / 'rnea_lq' / 'model.json').read_text())
    assert saved['hyperparameters']['friction'] == result.best_params['friction']


def test_a_network_sweep_reports_every_epochs_validation_loss_to_the_pruner(
    bag, tmp_path, mabi, monkeypatch
):
    reported: list[int] = []
    original = optuna.trial.Trial.report

    def spy(self, value, step):
        reported.append(step)
        return original(self, value, step)

    monkeypatch.setattr(optuna.trial.Trial, 'report', spy)
    result = run_sweep(
        [bag], mabi, 'motor', 'mlp', tmp_path, trials=2, max_seconds_per_trial=2.0,
        progress=False, seed=0,
    )  # fmt: skip
    # Each trial reports steps 0, 1, 2, ... (one per epoch) and the next trial starts at 0.
    assert reported
    assert reported[0] == 0
    steps = np.diff(reported)
    assert np.all((steps == 1) | (np.asarray(reported[1:]) == 0))
    assert set(result.best_params) <= set(SEARCH_SPACES['mlp'])


def test_every_search_space_names_fields_of_its_kind(mabi):
    for kind, space in SEARCH_SPACES.items():
        names = set(make_model(kind, mabi).config.__dataclass_fields__)
        assert set(space) <= names, kind


def test_bad_sweeps_are_refused_with_the_reason(bag, tmp_path, mabi):
    with pytest.raises(ConfigError, match='no search space'):
        run_sweep([bag], mabi, 'motor', 'rnea_effects', tmp_path, trials=1, progress=False)
    with pytest.raises(ConfigError, match='unknown model kind'):
        run_sweep([bag], mabi, 'motor', 'magic', tmp_path, trials=1, progress=False)
    with pytest.raises(ConfigError, match='--trials must be >= 1'):
        run_sweep([bag], mabi, 'motor', 'mlp', tmp_path, trials=0, progress=False)
    for storage in ('nosuchdb://nowhere', 'redis://localhost', 'mysql://u@localhost/db', 'x.db'):
        with pytest.raises(
            ConfigError, match=r'is no storage this tool supports: give sqlite:///'
        ):
            run_sweep(
                [bag], mabi, 'motor', 'rnea_lq', tmp_path, trials=1, progress=False,
                storage=storage,
            )  # fmt: skip
    bad = tmp_path / 'bad.yaml'
    bad.write_text('mlp: 3\n')
    code = cli([
        'train', '--bag', str(bag), '--models', 'rnea_lq', '--out', str(tmp_path / 'r'),
        '--hyper-file', str(bad), '--quiet',
    ])  # fmt: skip
    assert code == 2


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return int(s.getsockname()[1])


@pytest.fixture
def postgres(tmp_path):
    """A PostgreSQL server of its own on loopback; skipped, saying why, when there is none.

    PostgreSQL refuses to run as root: as root the server programs run as the postgres user.
    """
    tools = {name: shutil.which(name) for name in ('initdb', 'pg_ctl')}
    if not all(tools.values()):
        pytest.skip('no PostgreSQL server programs (initdb, pg_ctl) on this machine')
    pytest.importorskip('psycopg', reason='psycopg is not installed')
    as_user: list[str] = []
    folder = tmp_path / 'pg'
    folder.mkdir()
    if os.geteuid() == 0:
        try:
            account = pwd.getpwnam('postgres')
        except KeyError:
            pytest.skip('running as root and there is no postgres user to run the server as')
        runuser = shutil.which('runuser')
        if runuser is None:
            pytest.skip('running as root without runuser to start the server as postgres')
        as_user = [runuser, '-u', 'postgres', '--']
        os.chown(folder, account.pw_uid, account.pw_gid)
        for parent in (tmp_path, *tmp_path.parents):
            if parent == Path('/'):
                break
            os.chmod(parent, os.stat(parent).st_mode | 0o011)  # let postgres traverse
    data, port = folder / 'data', _free_port()
    subprocess.run([*as_user, tools['initdb'], '-D', str(data), '-A', 'trust', '-U', 'sweep'],
                   check=True, capture_output=True)  # fmt: skip
    options = f'-p {port} -k {folder} -c listen_addresses=127.0.0.1'
    subprocess.run([*as_user, tools['pg_ctl'], '-D', str(data), '-o', options, '-w', 'start',
                    '-l', str(folder / 'pg.log')], check=True, capture_output=True)  # fmt: skip
    try:
        yield f'postgresql+psycopg://sweep@127.0.0.1:{port}/postgres'
    finally:
        subprocess.run([*as_user, tools['pg_ctl'], '-D', str(data), '-m', 'fast', '-w', 'stop'],
                       capture_output=True, check=False)  # fmt: skip


def test_two_workers_share_one_study_through_postgresql(bag, tmp_path, postgres):
    workers = [_worker(bag, tmp_path / f'w{k}', postgres, 2, seed=k) for k in range(2)]
    _finish(workers)
    assert len(_complete(postgres)) == 4


def test_a_duplicate_table_is_a_lost_schema_race_and_a_syntax_error_is_not(postgres):
    sqlalchemy = pytest.importorskip('sqlalchemy')
    engine = sqlalchemy.create_engine(postgres)
    errors = []
    try:
        with engine.begin() as connection:
            connection.execute(sqlalchemy.text('CREATE TABLE raced (k INTEGER)'))
        for statement in ('CREATE TABLE raced (k INTEGER)', 'CREATE TABEL nonsense'):
            with (
                pytest.raises(sqlalchemy.exc.ProgrammingError) as caught,
                engine.begin() as connection,
            ):
                connection.execute(sqlalchemy.text(statement))
            errors.append(caught.value)
    finally:
        engine.dispose()
    assert lost_schema_race(errors[0])
    assert not lost_schema_race(errors[1])
