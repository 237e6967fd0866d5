"""The fault-injection suite's parts: outcomes, cases, the classifying runners and the fixtures.

``benchmarks/faults.py`` runs the suite; the case catalogues are ``fault_cases_recordings.py``
(bags, logs, replay, recovery) and ``fault_cases_settings.py`` (settings, artifacts, the
predictor's core, configs, the other doors).
"""

from __future__ import annotations

import contextlib
import io
import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ROBOT_FILE = REPO / 'config' / 'mabi_max100.yaml'
KINDS = ('clear_error', 'handled', 'silently_accepted', 'traceback', 'data_lost')


@dataclass(frozen=True)
class Outcome:
    """How one case ended: its class and what the door said."""

    kind: str
    said: str


@dataclass(frozen=True)
class Case:
    """One fault: a name, the door it goes through, and how to run it."""

    name: str
    door: str
    run: Callable[[], Outcome]


def cli(argv: list[str], *, expect: tuple[str, ...], handled: tuple[str, ...] = ()) -> Outcome:
    """Run ``id-learning argv`` in-process; a refusal must name every word in ``expect``."""
    from id_learning.cli.main import main

    err, out = io.StringIO(), io.StringIO()
    log = logging.StreamHandler(err)  # warnings go to the stderr of this case
    log.setLevel(logging.WARNING)
    logging.getLogger().addHandler(log)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            status = main(argv)
    except SystemExit as exit_:  # argparse refuses bad flags with exit 2
        status = exit_.code if isinstance(exit_.code, int) else 1
    except Exception as error:  # what the fault suite is there to find
        return Outcome('traceback', f'{type(error).__name__}: {error}')
    finally:
        logging.getLogger().removeHandler(log)
    said = (err.getvalue() + out.getvalue()).strip()
    if status != 0:
        missing = [word for word in expect if word.lower() not in said.lower()]
        return Outcome('clear_error' if not missing else 'silently_accepted', said[-400:])
    if handled and all(word.lower() in said.lower() for word in handled):
        return Outcome('handled', said[-400:])
    return Outcome('silently_accepted', said[-400:])


def raises(run: Callable[[], object], error: type[Exception], expect: tuple[str, ...]) -> Outcome:
    """A core call that must raise ``error`` naming every word in ``expect``."""
    try:
        run()
    except error as refused:
        text = str(refused)
        missing = [word for word in expect if word.lower() not in text.lower()]
        return Outcome('clear_error' if not missing else 'silently_accepted', text[-400:])
    except Exception as other:
        return Outcome('traceback', f'{type(other).__name__}: {other}')
    return Outcome('silently_accepted', 'accepted')


# -- fixtures -------------------------------------------------------------------------------------
@dataclass
class Fixtures:
    """What the cases break: a clean recording and bag, an artifact, an import log."""

    root: Path
    robot: object
    recording: object
    bag: Path
    run_dir: Path | None = None

    @property
    def artifact(self) -> Path:
        assert self.run_dir is not None
        return self.run_dir / 'models' / 'rnea_lq'

    def path(self, name: str) -> Path:
        return self.root / name


def build_fixtures(root: Path, *, train: bool) -> Fixtures:
    from id_learning.dataset.recording import load_recording, write_recording
    from id_learning.robot import load_robot_config
    from id_learning.training import train_run
    from id_learning.twin import load_twin_config, simulate, write_twin_output

    robot = load_robot_config(ROBOT_FILE)
    config = load_twin_config(REPO / 'config/twin_default.yaml', {'seed': 91})
    config = replace(config, excitation=replace(config.excitation, duration_s=26.0))
    twin = write_twin_output(simulate(config), config, root / 'twin')
    recording = load_recording(twin, robot)
    bag = write_recording(recording, root / 'clean', robot.topics)
    fixtures = Fixtures(root, robot, recording, bag)
    if train:
        run = train_run([twin], robot, 'motor', ['rnea_lq'], root / 'run', progress=False)
        fixtures.run_dir = run.out
    return fixtures


def broken_bag(fx: Fixtures, name: str, **changes: object) -> Path:
    """The clean recording with some arrays changed, written as a contract bag."""
    from id_learning.dataset.recording import write_recording

    return write_recording(replace(fx.recording, **changes), fx.path(name), fx.robot.topics)


def with_value(array: np.ndarray, sample: int, joint: int, value: float) -> np.ndarray:
    out = np.array(array, dtype=float, copy=True)
    out[sample, joint] = value
    return out
