"""Two sessions adapting on one artifact never overwrite each other's learning.

Probe A06: two predictors with ``adaptation:=rls`` on the same artifact both continued from the
stored state (954 updates); A saved 1689; B then saved 'on top of 954 earlier (1940 in all)' over
A's file without a word. Now the session that finds the file changed since it read it writes its
own state to a side file beside it and warns naming both, its learning not merged. The loop is
driven without ROS; the artifact is a model.json holding only its ``artifact_sha256``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from id_learning.models.artifact import ARTIFACT_HASH, METADATA_FILE
from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.predictor.adaptation_store import adaptation_path
from id_learning.robot.config import RobotConfig

SHA = 'c3' * 32


def _model(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    document = {'format': 'id_learning.model/1', ARTIFACT_HASH: SHA}
    (folder / METADATA_FILE).write_text(json.dumps(document), encoding='utf-8')
    return folder


def _started(robot: RobotConfig, artifact: Path) -> AdaptationLoop:
    loop = AdaptationLoop.for_robot(robot, robot.joints, AdaptationConfig())
    loop.load(artifact, robot.joints)
    return loop


def _learn(loop: AdaptationLoop, robot: RobotConfig, samples: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = len(robot.joints)
    before = loop.session_updates
    for k in range(samples):
        stamp = 1_000_000 + k * 8_000_000
        loop.serve(stamp, (rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(n)), np.zeros(n))
        effort = list(rng.normal(0.0, 0.5, n))
        loop.measured_message(stamp, list(robot.joints), effort, list(robot.joints))
    assert loop.session_updates == before + samples


def _sides(path: Path) -> list[Path]:
    return sorted(p for p in path.parent.iterdir() if p.name.startswith(f'{path.name}.session-'))


def test_the_second_session_to_save_keeps_the_first_ones_file_and_writes_beside_it(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    artifact = _model(tmp_path / 'run' / 'models' / 'rnea_id')
    path = adaptation_path(artifact)
    earlier = _started(mabi, artifact)
    _learn(earlier, mabi, 30, seed=1)
    earlier.finish(artifact, mabi.joints)

    a, b = _started(mabi, artifact), _started(mabi, artifact)
    assert a.base is not None
    assert a.base.updates_before == 30
    _learn(a, mabi, 20, seed=2)
    _learn(b, mabi, 25, seed=3)
    warn_a, line_a = a.finish(artifact, mabi.joints)
    assert not warn_a, line_a
    saved_by_a = path.read_text()
    assert json.loads(saved_by_a)['updates_total'] == 50

    warn_b, line_b = b.finish(artifact, mabi.joints)
    assert warn_b, line_b
    assert path.read_text() == saved_by_a  # A's learning is kept
    (side,) = _sides(path)
    assert json.loads(side.read_text())['updates'] == 25
    assert json.loads(side.read_text())['updates_total'] == 55
    assert str(path) in line_b
    assert str(side) in line_b
    assert 'not merged' in line_b


def test_two_sessions_starting_without_a_file_do_not_overwrite_each_other(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    artifact = _model(tmp_path / 'rnea_id')
    path = adaptation_path(artifact)
    a, b = _started(mabi, artifact), _started(mabi, artifact)
    _learn(a, mabi, 10, seed=4)
    _learn(b, mabi, 12, seed=5)
    assert not a.finish(artifact, mabi.joints)[0]
    warn, line = b.finish(artifact, mabi.joints)
    assert warn, line
    assert json.loads(path.read_text())['updates'] == 10
    (side,) = _sides(path)
    assert json.loads(side.read_text())['updates'] == 12


def test_a_session_saving_twice_over_its_own_file_is_not_a_conflict(
    mabi: RobotConfig, tmp_path: Path
) -> None:
    artifact = _model(tmp_path / 'rnea_id')
    path = adaptation_path(artifact)
    loop = _started(mabi, artifact)
    _learn(loop, mabi, 10, seed=6)
    assert loop.save(artifact, mabi.joints) is not None
    _learn(loop, mabi, 5, seed=7)
    warn, line = loop.finish(artifact, mabi.joints)
    assert not warn, line
    assert json.loads(path.read_text())['updates'] == 15
    assert not _sides(path)
