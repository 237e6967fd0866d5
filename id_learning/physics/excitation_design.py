"""Excitation designed for identification: a well-conditioned regressor over joint space.

The study's excitation (``record.excitation``) draws each Fourier segment at random. Here each
segment is drawn ``candidates`` times, every draw scaled into the limits the same way, and the
draw kept that, with the segments kept before it, gives the identification regressor the
smallest condition number while covering most of joint space (every pair of joints' ranges).
The identification's columns are the robot's base inertial parameters (``base_parameters``)
and, per joint, a rotor inertia, viscous and Coulomb friction and an offset (those the
inertial ones span dropped); each column is scaled by its norm over random states within the
limits, so that the condition number compares designs, not units.

Greedy selection of whole segments keeps every guarantee of the random design (rest at the
home pose between segments, every limit checked on a dense grid) and needs no gradient. The
figures of merit are reported beside those of the first draw of every segment, which is the
random design the twin records by default.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import linalg
from tqdm import tqdm

from id_learning.config_io import DuplicateKeyError, loads_unique, read_capped
from id_learning.errors import ConfigError
from id_learning.physics.base_parameters import BaseParameters, base_parameters
from id_learning.physics.rigid_body import RigidBodyDynamics
from id_learning.record.excitation import (
    CHECK_OVERSAMPLING,
    ExcitationConfig,
    ExcitationTrajectory,
    FourierSegment,
    check_bandwidth,
    check_limits,
    home_pose,
    random_segment,
)
from id_learning.robot.config import JointLimits, RobotConfig

__all__ = [
    'COVERAGE_BINS',
    'COVERAGE_WEIGHT',
    'DESIGN_FILE',
    'TRAJECTORY_CSV',
    'DesignReport',
    'ExcitationDesign',
    'IdentificationColumns',
    'design_for_identification',
    'load_design',
    'write_design',
]

_LOG = logging.getLogger(__name__)

#: Bins per joint over the reachable position range; coverage counts the cells of joint pairs.
COVERAGE_BINS = 8
#: Weight of the coverage (0..1) against the log10 condition number in a draw's score.
COVERAGE_WEIGHT = 0.5
#: States of a segment the regressor is evaluated at (evenly in time).
POINTS_PER_SEGMENT = 100
#: The designed excitation file's format, and the reference bag's first stamp (2026-01-01).
DESIGN_FORMAT = 'id_learning.excitation/1'
START_NS = 1_767_225_600_000_000_000


class IdentificationColumns:
    """The identification regressor's columns at states, each scaled to a comparable size.

    Base inertial parameters, then per joint rotor inertia (a), viscous (v), Coulomb (sign v)
    and an offset: what ``physics.identification`` fits, without the effects it may add.
    """

    def __init__(self, dynamics: RigidBodyDynamics, limits: JointLimits) -> None:
        self.dynamics = dynamics
        self.base: BaseParameters = base_parameters(dynamics, limits)
        rng = np.random.default_rng(20261128)
        n = dynamics.n_joints
        q = rng.uniform(limits.position_lower, limits.position_upper, size=(400, n))
        v = rng.uniform(-1.0, 1.0, size=(400, n)) * limits.velocity
        a = rng.uniform(-1.0, 1.0, size=(400, n)) * limits.acceleration
        raw = self._raw(q, v, a)
        norms = np.linalg.norm(raw, axis=0)
        self.scale = np.where(norms > 0, norms, 1.0)
        # A drive column the inertial ones span (joint 1's rotor inertia is its link's Izz) is
        # no parameter of its own: only independent columns are kept.
        _, r, pivots = linalg.qr(raw / self.scale, mode='economic', pivoting=True)
        diagonal = np.abs(np.diag(r))
        self.keep = np.sort(pivots[: int(np.sum(diagonal > 1e-8 * diagonal[0]))])

    @property
    def count(self) -> int:
        """The number of independent columns."""
        return len(self.keep)

    def _raw(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        n = self.dynamics.n_joints
        inertial = np.einsum('bjp,rp->bjr', self.dynamics.regressor(q, v, a), self.base.matrix)
        drive = np.zeros((len(q), n, 4 * n))
        for j in range(n):
            drive[:, j, 4 * j : 4 * j + 4] = np.stack(
                [a[:, j], v[:, j], np.sign(v[:, j]), np.ones(len(q))], axis=1
            )
        return np.concatenate([inertial, drive], axis=2).reshape(len(q) * n, -1)

    def __call__(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """(B * n, count) the scaled columns at B states (q, v, a each (B, n))."""
        return (self._raw(q, v, a) / self.scale)[:, self.keep]


def condition(gram: np.ndarray) -> float:
    """The condition number of a regressor Y from its Gram matrix Y^T Y (inf when singular)."""
    eigenvalues = np.linalg.eigvalsh(gram)
    low, high = float(eigenvalues[0]), float(eigenvalues[-1])
    return math.inf if low <= high * 1e-15 else math.sqrt(high / low)


def coverage(counts: np.ndarray) -> float:
    """The share of joint-pair position cells (pairs, bins, bins) that hold a sample."""
    return float(np.mean(counts > 0))


@dataclass(frozen=True)
class DesignReport:
    """Figures of merit of a designed excitation beside the random one.

    Attributes:
        columns: the identification's columns (base parameters and drive terms).
        condition: the regressor's condition number over the whole designed excitation.
        condition_random: the same for the first draw of every segment (the random design).
        coverage, coverage_random: the share of the cells of every pair of joints' reachable
            ranges visited (``COVERAGE_BINS`` bins per joint), designed and random.
        candidates: draws per segment.
    """

    columns: int
    condition: float
    condition_random: float
    coverage: float
    coverage_random: float
    candidates: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures (a singular regressor's condition number as None)."""
        return {
            key: (None if isinstance(value, float) and math.isinf(value) else value)
            for key, value in self.__dict__.items()
        }


@dataclass(frozen=True, eq=False)
class ExcitationDesign:
    """A designed excitation and its figures of merit."""

    trajectory: ExcitationTrajectory
    report: DesignReport


def _total(arrays: list[np.ndarray]) -> np.ndarray:
    return np.asarray(np.sum(np.stack(arrays), axis=0))


@dataclass(frozen=True, eq=False)
class _Draw:
    """A candidate segment, its regressor's Gram matrix and the joint-pair cells it visits."""

    segment: FourierSegment
    gram: np.ndarray
    cells: np.ndarray


class _Drawer:
    """Draws segments within the limits (``record.excitation.random_segment``) and scores sets."""

    def __init__(
        self,
        config: ExcitationConfig,
        robot: RobotConfig,
        home: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
        limits, period_s = robot.limits, robot.ipo_period_s
        self.config, self.home, self.rng = config, home, rng
        self.omega = 2.0 * math.pi * config.base_frequency_hz
        dense = int(config.period_s / period_s * CHECK_OVERSAMPLING) + 1
        self.grid = np.linspace(0.0, config.period_s, dense)
        self.points = np.linspace(0.0, config.period_s, POINTS_PER_SEGMENT, endpoint=False)
        self.reach_low = config.position_fraction * (home - limits.position_lower)
        self.reach_high = config.position_fraction * (limits.position_upper - home)
        self.vel_max = config.velocity_fraction * limits.velocity
        self.acc_max = config.acceleration_fraction * limits.acceleration
        self.columns = IdentificationColumns(RigidBodyDynamics.from_config(robot), limits)
        low, high = home - self.reach_low, home + self.reach_high
        self.edges = np.linspace(low, high, COVERAGE_BINS + 1, axis=1)  # (n, bins + 1)
        self.pairs = list(itertools.combinations(range(len(home)), 2))

    def __call__(self) -> _Draw:
        segment = random_segment(
            self.rng, len(self.home), self.config.harmonics, self.omega, self.home,
            reach_low=self.reach_low, reach_high=self.reach_high,
            vel_max=self.vel_max, acc_max=self.acc_max, grid=self.grid,
        )  # fmt: skip
        q, v, a = segment.evaluate(self.points)
        y = self.columns(q, v, a)
        bins = COVERAGE_BINS
        cells = np.zeros((max(len(self.pairs), 1), bins, bins))
        for k, (i, j) in enumerate(self.pairs):
            cells[k] = np.histogram2d(q[:, i], q[:, j], bins=(self.edges[i], self.edges[j]))[0]
        return _Draw(segment, y.T @ y, cells)

    def score(self, draws: list[_Draw]) -> float:
        """log10 of the set's condition number less the weighted share of cells it visits."""
        gram, cells = _total([d.gram for d in draws]), _total([d.cells for d in draws])
        return math.log10(condition(gram)) - COVERAGE_WEIGHT * coverage(cells)


def design_for_identification(
    config: ExcitationConfig,
    robot: RobotConfig,
    rng: np.random.Generator,
    *,
    candidates: int = 16,
    progress: bool = False,
) -> ExcitationDesign:
    """An excitation of ``config``'s shape whose segments are chosen for identification.

    Two passes: each segment in turn is the best of ``candidates`` draws given those kept
    before it; then each is drawn again and replaced where a draw scores better given all the
    others (the score of the whole, not of a prefix).

    Raises:
        ConfigError: as ``record.excitation.design_excitation`` (home outside the limits, a
            harmonic at or above Nyquist, a limit violated on the check grid).
    """
    limits, period_s = robot.limits, robot.ipo_period_s
    home = home_pose(config, limits, robot.joints)
    check_bandwidth(config.base_frequency_hz, config.harmonics, period_s, 'excitation')
    draw = _Drawer(config, robot, home, rng)
    count = config.segment_count
    kept: list[_Draw] = []
    random: list[_Draw] = []
    steps = tqdm(total=2 * count, desc='designing', unit='segment', disable=not progress)
    for _ in range(count):  # greedy: the best next segment
        draws = [draw() for _ in range(candidates)]
        random.append(draws[0])
        kept.append(min(draws, key=lambda d: draw.score([*kept, d])))
        steps.update()
    for k in range(count):  # refinement: the best segment k given all the others
        others = kept[:k] + kept[k + 1 :]
        draws = [kept[k], *(draw() for _ in range(candidates - 1))]
        kept[k] = min(draws, key=lambda d: draw.score([*others, d]))
        steps.update()
    steps.close()
    trajectory = ExcitationTrajectory(
        tuple(d.segment for d in kept), home, config.period_s, config.rest_s
    )
    check_limits(trajectory, limits, period_s / CHECK_OVERSAMPLING, robot.joints)
    report = DesignReport(
        columns=draw.columns.count,
        condition=condition(_total([d.gram for d in kept])),
        condition_random=condition(_total([d.gram for d in random])),
        coverage=coverage(_total([d.cells for d in kept])),
        coverage_random=coverage(_total([d.cells for d in random])),
        candidates=candidates,
    )
    return ExcitationDesign(trajectory, report)


#: Beside the reference bag: the coefficients with the figures, and the samples for a CNC.
DESIGN_FILE, TRAJECTORY_CSV = 'excitation.json', 'trajectory.csv'
#: The largest design file read [bytes]: a day's design (3456 segments) takes about 7 MB.
MAX_DESIGN_BYTES = 64 * 2**20


def write_design(design: ExcitationDesign, robot: RobotConfig, out: Path) -> Path:
    """Write a designed excitation as a reference bag the replay plays, with its files beside.

    ``out`` holds the bag (``/joint_states`` positions and velocities at the IPO period, no
    label: a reference, not a recording), ``excitation.json`` (the exact coefficients, which
    the twin reads as ``excitation.file``, and the figures of merit) and ``trajectory.csv``
    (time, then per joint position, velocity and acceleration, SI units) for a controller that
    reads neither.
    """
    from id_learning.dataset.recording import Recording, write_recording

    trajectory = design.trajectory
    period = robot.ipo_period_s
    t = np.arange(round(trajectory.duration_s / period) + 1) * period
    q, v, a = trajectory.evaluate(t)
    stamps = START_NS + np.round(t * 1e9).astype(np.int64)
    recording = Recording(robot.joints, stamps, q, v, None, None, source=str(out))
    write_recording(recording, out, robot.topics, overwrite=True)
    document = {
        'format': DESIGN_FORMAT,
        'robot': robot.name,
        'joints': list(robot.joints),
        'ipo_period_s': period,
        'report': design.report.to_dict(),
        'trajectory': trajectory.to_dict(),
    }
    (out / DESIGN_FILE).write_text(json.dumps(document, indent=1) + '\n', encoding='utf-8')
    header = ['t_s'] + [f'{kind}_{joint}' for kind in ('q', 'qd', 'qdd') for joint in robot.joints]
    table = np.column_stack([t, q, v, a])
    np.savetxt(out / TRAJECTORY_CSV, table, delimiter=',', header=','.join(header), comments='')
    return out


_DOCUMENT_KEYS = {'format', 'robot', 'joints', 'ipo_period_s', 'report', 'trajectory'}
_TRAJECTORY_KEYS = {'home', 'period_s', 'rest_s', 'omega_rad_s', 'segments'}
_SEGMENT_KEYS = {'a', 'b', 'q0'}


def _keys(mapping: object, allowed: set[str], where: str) -> dict[str, Any]:
    """``mapping`` as a dict holding exactly the ``allowed`` keys (names the odd ones)."""
    if not isinstance(mapping, dict):
        raise ConfigError(f'{where}: expected a mapping, got {type(mapping).__name__}')
    if unknown := sorted(set(mapping) - allowed):
        raise ConfigError(f'{where}: unknown key(s) {unknown}; known: {sorted(allowed)}')
    if missing := sorted(allowed - set(mapping)):
        raise ConfigError(f'{where}: missing key(s) {missing}')
    return mapping


def _array(value: object, shape: tuple[int, ...], where: str) -> np.ndarray:
    """A finite float array of ``shape`` (-1: any length, the same for every such array)."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise ConfigError(f'{where}: not an array of numbers: {err}') from err
    fits = array.ndim == len(shape) and all(
        n in (-1, size) for n, size in zip(shape, array.shape, strict=True)
    )
    if not fits or (len(shape) == 2 and array.shape[1] == 0):
        wanted = ', '.join('harmonics' if n == -1 else str(n) for n in shape)
        raise ConfigError(f'{where}: shape {array.shape}, expected ({wanted})')
    if not np.isfinite(array).all():
        raise ConfigError(f'{where}: holds a value that is not a finite number')
    return array


def _trajectory(data: object, n: int, where: str) -> ExcitationTrajectory:
    """The designed trajectory of a document, every number checked (``load_design``)."""
    data = _keys(data, _TRAJECTORY_KEYS, where)
    period, rest, omega = (
        float(_array(data[key], (), f'{where}.{key}'))
        for key in ('period_s', 'rest_s', 'omega_rad_s')
    )
    if not period > 0 or not rest >= 0:
        raise ConfigError(f'{where}: period_s {period:g} must be > 0 and rest_s {rest:g} >= 0')
    if not math.isclose(omega * period, 2 * math.pi, rel_tol=1e-9):
        raise ConfigError(f'{where}: omega_rad_s {omega:g} is not 2 pi / period_s {period:g}')
    segments = data['segments']
    if not isinstance(segments, list) or not segments:
        raise ConfigError(f'{where}.segments: no segment: nothing would move')
    parts = []
    for k, given in enumerate(segments):
        at = f'{where}.segments[{k}]'
        segment = _keys(given, _SEGMENT_KEYS, at)
        a = _array(segment['a'], (n, -1), f'{at}.a')
        b = _array(segment['b'], a.shape, f'{at}.b')
        parts.append(FourierSegment(a, b, _array(segment['q0'], (n,), f'{at}.q0'), omega))
    if len({part.a.shape for part in parts}) > 1:
        raise ConfigError(f'{where}.segments: the segments hold different numbers of harmonics')
    return ExcitationTrajectory(tuple(parts), _array(data['home'], (n,), f'{where}.home'),
                                period, rest)  # fmt: skip


def _read_document(path: Path, where: str) -> object:
    """The JSON of a design file; a key given twice in one object is refused.

    ``json`` keeps the last of two equal keys without a word: an edited file would play another
    design than the one read.

    Raises:
        ConfigError: unreadable (a device, too large, not UTF-8), not JSON, or a repeated key.
    """
    try:
        text = read_capped(path, 'a designed excitation', MAX_DESIGN_BYTES).decode('utf-8')
    except ConfigError as err:  # names the file
        raise ConfigError(f'{where}: {err}') from err
    except UnicodeDecodeError as err:
        raise ConfigError(f'{where}: {path}: cannot read a designed excitation: {err}') from err
    at = f'{where}: {path}'
    try:
        return loads_unique(text)
    except DuplicateKeyError as err:
        raise ConfigError(
            f'{at}: the key {err.key!r} is given twice in one object ({err.values[0]} and '
            f'{err.values[1]}): which one holds is ambiguous; keep one, or design the excitation '
            'again'
        ) from err
    except json.JSONDecodeError as err:
        raise ConfigError(f'{at}: cannot read a designed excitation: {err}') from err


def load_design(path: Path, robot: RobotConfig, where: str) -> ExcitationTrajectory:
    """The trajectory of an ``excitation.json`` for ``robot``, checked against its limits.

    Every key and number is checked (finite, shaped for the robot's joints, rests not
    negative, at least one segment), and the file must be for the robot's joints and IPO
    period; another robot name with the same joints is said in a warning.

    Raises:
        ConfigError: unreadable, a key given twice, of another format, joints or period,
            damaged, or beyond the limits (naming the key, the joint, the time).
    """
    document = _read_document(Path(path), where)
    if not isinstance(document, dict) or document.get('format') != DESIGN_FORMAT:
        raise ConfigError(
            f'{where}: {path}: not an {DESIGN_FILE} written by id-learning excitation'
        )
    document = _keys(document, _DOCUMENT_KEYS, f'{where}: {path}')
    if document['joints'] != list(robot.joints):
        raise ConfigError(
            f'{where}: {path}: designed for joints {document["joints"]} of '
            f'{document["robot"]!r}, not {list(robot.joints)} of {robot.name!r}'
        )
    period = document['ipo_period_s']
    if not isinstance(period, (int, float)) or not math.isclose(period, robot.ipo_period_s):
        raise ConfigError(
            f'{where}: {path}: designed for an IPO period of {period!r} s, {robot.name!r} has '
            f'{robot.ipo_period_s:g} s: design it again for this robot'
        )
    if document['robot'] != robot.name:
        _LOG.warning('%s: %s was designed for %r, played on %r (the same joints)',
                     where, path, document['robot'], robot.name)  # fmt: skip
    trajectory = _trajectory(
        document['trajectory'], robot.n_joints, f'{where}: {path}: trajectory'
    )
    check_limits(trajectory, robot.limits, robot.ipo_period_s / CHECK_OVERSAMPLING, robot.joints)
    return trajectory
