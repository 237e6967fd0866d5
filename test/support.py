"""Helpers shared by tests (importable: pytest puts test/ on sys.path)."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def twin_config(duration_s: float = 30.0, effects: dict | None = None, **overrides):
    """A short twin config from config/twin_default.yaml; ``effects`` replaces the effect map."""
    from id_learning.twin import load_twin_config

    extra = dict(overrides)
    if effects is not None:
        extra['effects'] = effects
    config = load_twin_config(REPO / 'config/twin_default.yaml', extra)
    return replace(config, excitation=replace(config.excitation, duration_s=duration_s))


#: The twin's default balancer (config/twin_default.yaml): arms 0.25 and 0.40 m on joint 2, so
#: an arm ratio of 0.625, shortest upright.
TWIN_SPRING = {
    'enabled': True,
    'joint': 'joint_2',
    'arm_base_m': 0.25,
    'arm_link_m': 0.40,
    'phase_rad': 0.0,
    'preload_n': 3000.0,
    'stiffness_n_per_m': 25000.0,
}

#: Hyper-parameters of the short training runs in tests: an MLP fit of two epochs.
FAST_HYPER = {'mlp': {'max_epochs': 2}}

#: Label cut-off of quick model tests [Hz]: the study's 0.3 Hz filter reads 11 s on either side,
#: too much for the seconds-long recordings a unit test fits on through the filter.
QUICK_CUTOFF_HZ = 2.0


def quick_preprocess(n_joints: int = 6, **overrides):
    """Preprocessing for quick fits: labels low-passed at QUICK_CUTOFF_HZ, default otherwise."""
    from id_learning.dataset.preprocess import PreprocessConfig

    return PreprocessConfig(cutoff_hz=(QUICK_CUTOFF_HZ,) * n_joints, **overrides)


def sine_recording(
    n_samples: int = 3000, period_s: float = 0.008, joints: tuple[str, ...] | None = None
):
    """A smooth synthetic recording in the bag contract's quantities (6 MABI joints by default)."""
    import numpy as np

    from id_learning.dataset.recording import Recording

    joints = joints or tuple(f'joint_{i}' for i in range(1, 7))
    n = len(joints)
    t = np.arange(n_samples) * period_s
    freq = 0.1 + 0.05 * np.arange(n)
    position = 0.5 * np.sin(2 * np.pi * freq * t[:, None])
    velocity = 0.5 * 2 * np.pi * freq * np.cos(2 * np.pi * freq * t[:, None])
    current = 2.0 * np.sin(2 * np.pi * freq * t[:, None] + 0.3)
    stamps = 1_767_225_600_000_000_000 + np.round(t * 1e9).astype(np.int64)
    return Recording(joints, stamps, position, velocity, current, None, source='sines')


def write_contract_bag(
    path: Path,
    recording,
    *,
    names_js: tuple[str, ...] | None = None,
    names_mc: tuple[str, ...] | None = None,
    stamps_mc=None,
    topics: tuple[str, ...] = ('/joint_states', '/motor_currents'),
    split_duration_ns: int | None = None,
) -> Path:
    """Write a bag sample by sample, with hooks to break the contract on purpose.

    ``split_duration_ns``: a new storage file every so many nanoseconds of log time.
    """
    import numpy as np

    from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state

    names_js = names_js or recording.joints
    names_mc = names_mc or recording.joints
    stamps_mc = recording.stamps_ns if stamps_mc is None else stamps_mc
    empty = np.empty(0)
    with BagWriter(path, split_duration_ns=split_duration_ns) as writer:
        for topic in topics:
            writer.add_topic(topic, JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            # Log (receive) times advance monotonically whatever the header stamps do.
            log_ns = int(recording.stamps_ns[0]) + k * 8_000_000
            if '/joint_states' in topics:
                writer.write(
                    '/joint_states',
                    log_ns,
                    encode_joint_state(
                        stamp,
                        names_js,
                        recording.position[k],
                        recording.velocity[k],
                        empty if recording.joint_torque is None else recording.joint_torque[k],
                    ),
                )
            if '/motor_currents' in topics:
                stamp_mc = int(stamps_mc[k])
                writer.write(
                    '/motor_currents',
                    log_ns,
                    encode_joint_state(stamp_mc, names_mc, empty, empty, recording.current[k]),
                )
    return path


def run_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``python -m id_learning.cli ARGS`` in the checkout, as a user runs it; never raises."""
    return subprocess.run(
        [sys.executable, '-m', 'id_learning.cli', *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=timeout,
        check=False,
    )


def ground_truth(bag: Path):
    """The twin's own record of a bag: its settings (JSON) and the sample stamps (NPZ)."""
    import json

    import numpy as np

    truth = json.loads((bag / 'ground_truth.json').read_text())
    with np.load(bag / 'ground_truth.npz') as arrays:
        return truth, arrays['stamps_ns']


def inspect_topic_rows(stdout: str) -> dict[str, list[str]]:
    """The cells of the inspect timing table, by topic (jitter 'std / p99' stays three cells)."""
    return {
        cells[0]: cells[1:]
        for cells in (line.split() for line in stdout.splitlines())
        if cells and cells[0] in ('/joint_states', '/motor_currents')
    }


@contextmanager
def no_hang(seconds: float = 20.0) -> Iterator[None]:
    """Fail, not hang, when code in this process blocks (opens a FIFO nobody writes): SIGALRM."""

    def expire(number: int, frame: object) -> None:
        raise TimeoutError(f'no answer within {seconds:g} s: it blocks (a FIFO opened?)')

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@contextmanager
def immutable(folder: Path) -> Iterator[Path]:
    """``folder`` made one nobody may write into, root included (``chattr +i``)."""
    import shutil

    import pytest

    if not shutil.which('chattr'):
        pytest.skip('chattr is not installed')
    if subprocess.run(['chattr', '+i', str(folder)], capture_output=True, check=False).returncode:
        pytest.skip('this file system has no immutable attribute')
    try:
        yield folder
    finally:
        subprocess.run(['chattr', '-i', str(folder)], check=True)
