"""The identification's least-squares problem: its layout, its rows, and the nonlinear searches.

``Problem`` stacks one recording's training part into a weighted, linearised system around the
current estimate (see ``physics.identification`` for the model and the method);
``choose_stribeck`` and ``choose_balancers`` pick the nonlinear settings (Stribeck velocity,
balancer geometry) with the linear parameters refitted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.statistics import estimate_noise
from id_learning.errors import ConfigError, DatasetError
from id_learning.physics.balancer import (
    BALANCER_PHASES,
    BALANCER_RATIOS,
    BALANCER_TERMS,
    balancer_basis,
)
from id_learning.physics.base_parameters import CadPrior
from id_learning.physics.identified import FRICTION_LAWS, RATE_STEP_S, friction_columns
from id_learning.physics.inertial import frame_parameter_map
from id_learning.physics.nominal import NominalModel
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS, RigidBodyDynamics
from id_learning.physics.terms import gravity_loaded_joints
from id_learning.robot.config import RobotConfig

__all__ = [
    'IdentificationConfig',
    'Layout',
    'NormalEquations',
    'Problem',
    'choose_balancers',
    'choose_stribeck',
]


@dataclass(frozen=True)
class IdentificationConfig:
    """What the identification estimates and how strongly it trusts the CAD model.

    Attributes:
        friction: friction laws per joint (motor target; joint torques carry no friction).
        smoothing_velocity: v_eps of the friction laws' smoothed sign [rad/s].
        stribeck_velocities: candidate Stribeck velocities v_s [rad/s]; the best per joint is
            kept.
        rotor_inertia: estimate the rotor inertias (motor target).
        label_gain: estimate a per-joint gain of the labels, the torque constant's error (motor
            target). Its global scale and the bodies' masses trade against each other: the
            priors settle it.
        offsets: estimate a torque offset per joint.
        delay: estimate a signal delay of the labels behind the positions (motor target:
            currents lag the encoders), tau(t - d) ~ tau - d (dtau/dq v + dtau/dv a); the part
            of the rate that needs the jerk is left out, as the (q, v, a) inputs carry none.
        payload: estimate a rigid payload (tool, spindle) at the robot's payload frame, all ten
            parameters, without a prior: the URDF does not know it; kept physical like a body.
        balancer: joints that carry a balancer: 'auto' (those whose nominal gravity torque
            sweeps at least ``balancer_min_share`` of their torque limit on the recording),
            'none', or comma-separated joint names. Its torque largely mimics the first moment
            of the link it holds, which the CAD prior then keeps from absorbing it.
        balancer_min_share: see ``balancer``.
        balancer_ratios: candidate ratios of a balancer's arms (``physics.balancer``); the
            best is refined per joint.
        balancer_phases: candidate phases of a balancer [rad] (0: shortest upright).
        prior: the CAD prior of the inertial parameters.
        rotor_rel_std: relative std of the datasheet rotor inertia.
        gain_std: std of the label gain around 0 (a datasheet torque constant's tolerance).
        iterations: linearisations of the bilinear terms (the first uses the URDF).
        solver: cvxpy solver of the constrained problem.
    """

    friction: tuple[str, ...] = FRICTION_LAWS
    smoothing_velocity: float = 0.005
    stribeck_velocities: tuple[float, ...] = (0.01, 0.02, 0.03, 0.05, 0.08)
    rotor_inertia: bool = True
    label_gain: bool = True
    offsets: bool = True
    delay: bool = True
    payload: bool = True
    balancer: str = 'auto'
    balancer_min_share: float = 0.05
    balancer_ratios: tuple[float, ...] = BALANCER_RATIOS
    balancer_phases: tuple[float, ...] = BALANCER_PHASES
    prior: CadPrior = field(default_factory=CadPrior)
    rotor_rel_std: float = 0.5
    gain_std: float = 0.05
    iterations: int = 3
    solver: str = 'CLARABEL'

    def __post_init__(self) -> None:
        """Check names and ranges, naming the key."""
        unknown = sorted(set(self.friction) - set(FRICTION_LAWS))
        if unknown:
            raise ConfigError(
                f'identification.friction: unknown law(s) {unknown}; known: {list(FRICTION_LAWS)}'
            )
        if not self.stribeck_velocities or min(self.stribeck_velocities) <= 0:
            raise ConfigError('identification.stribeck_velocities: need positive velocities')
        if self.iterations < 1:
            raise ConfigError(f'identification.iterations must be >= 1, got {self.iterations}')
        if not self.balancer_ratios or not all(0 < r < 1 for r in self.balancer_ratios):
            raise ConfigError(
                f'identification.balancer_ratios must lie in (0, 1), got {self.balancer_ratios}'
            )
        if not self.balancer_phases:
            raise ConfigError('identification.balancer_phases: need at least one phase')
        for key in ('smoothing_velocity', 'rotor_rel_std', 'gain_std'):
            if not getattr(self, key) > 0:
                raise ConfigError(f'identification.{key} must be > 0, got {getattr(self, key)}')


@dataclass(eq=False)
class Layout:
    """Where each parameter sits in the stacked vector x, with its prior."""

    names: list[str] = field(default_factory=list)
    prior_mean: list[float] = field(default_factory=list)
    prior_std: list[float] = field(default_factory=list)  # inf: no prior
    blocks: dict[str, slice] = field(default_factory=dict)

    def add(self, block: str, names: list[str], mean: np.ndarray, std: np.ndarray | float) -> None:
        """Append a block of parameters with their prior mean and std (inf: no prior)."""
        start = len(self.names)
        self.names += names
        self.prior_mean += list(np.broadcast_to(mean, len(names)))
        self.prior_std += list(np.broadcast_to(std, len(names)))
        self.blocks[block] = slice(start, len(self.names))

    def __len__(self) -> int:
        return len(self.names)


class Problem:
    """The stacked, weighted least-squares problem of one recording's training part."""

    def __init__(self, dataset: Dataset, robot: RobotConfig, config: IdentificationConfig):
        self.dataset, self.robot, self.config = dataset, robot, config
        self.n = robot.n_joints
        self.motor = dataset.target == 'motor'
        self.laws = tuple(law for law in FRICTION_LAWS if law in config.friction and self.motor)
        self.nominal = RigidBodyDynamics.from_config(robot)
        self.theta0 = self.nominal.inertial_parameters()
        # The noise level from a contiguous stretch: the training part, or under a shuffled
        # split the whole recording (its spectrum needs neighbouring samples; only the noise
        # level, no label value, enters the fit from it).
        stretch = slice(None) if dataset.is_shuffled else slice(0, dataset.n_train)
        noise = estimate_noise(
            dataset.tau_raw[stretch], dataset.cutoff_hz, dataset.period_s, dataset.filter_order
        )
        tau = noise.correlation_samples
        sigma = np.maximum(noise.filtered_std_nm, 1e-6 * robot.limits.torque)
        self.step = max(1, int(tau.min() // 6))
        self.rows = dataset.train_rows[:: self.step]
        if len(self.rows) < 10:
            raise DatasetError(
                f'{dataset.source}: the training part has {dataset.n_train} samples, too few to '
                'identify the rigid body'
            )
        # Each kept row holds spacing / tau independent samples of noise sigma (spacing: the
        # step in time between kept rows; wider under a shuffled split): the data term is then a
        # log-likelihood on the scale of the prior's.
        spacing = float(self.step)
        if dataset.is_shuffled:
            spacing = (self.rows[-1] - self.rows[0] + 1) / len(self.rows)
        self.row_weight = np.sqrt(spacing / tau) / sigma
        self.noise_std = sigma
        q, v, a = dataset.q, dataset.v, dataset.a
        self.v = v
        self.regressor = self.nominal.regressor(q, v, a)  # (N, n, 10 B) unfiltered
        if config.payload:
            body, self.payload_map = frame_parameter_map(self.nominal, robot.payload_frame)
            self.payload_body = body
            block = slice(N_INERTIAL_PARAMETERS * body, N_INERTIAL_PARAMETERS * (body + 1))
            # A payload acts through its carrying body's columns: Y theta += Y_body T p.
            payload = self.regressor[:, :, block] @ self.payload_map
            self.regressor = np.concatenate([self.regressor, payload], axis=2)
        self.filtered_regressor = [
            self._filter(self.regressor[:, j, :], j)[self.rows] for j in range(self.n)
        ]
        self.filtered_rate = self._regressor_rate(q, v, a) if self.has_delay else None
        gear = robot.drives.gear_ratio
        self.rotor_column = self._filter(a * gear**2)[self.rows] if self.motor else None
        self.label = dataset.tau[self.rows]
        self.balancer_joints = self._balancer_joints()
        self.q = q
        #: Per balancer joint, its geometry (ratio, phase), and its basis (N, 3), unfiltered, and
        #: filtered on the kept rows.
        self.geometry: dict[int, tuple[float, float]] = {}
        self._balancer_rates: dict[tuple[int, float, float], np.ndarray] = {}
        self.balancer_basis: dict[int, np.ndarray] = {}
        self.balancer_columns: dict[int, np.ndarray] = {}
        for j in self.balancer_joints:
            self.set_geometry(j, float(np.median(config.balancer_ratios)), 0.0)
        self.layout = self._layout()

    @property
    def has_delay(self) -> bool:
        """Whether a signal delay is estimated."""
        return self.motor and self.config.delay

    def _regressor_rate(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> list[np.ndarray]:
        """Per joint, the filtered rate of the regressor along the motion, without the jerk.

        (dY/dq v + dY/dv a) theta is the torque's rate when a stays put: a central difference
        along (v, a) of the regressor, which is linear in theta.
        """
        h = RATE_STEP_S
        ahead = self.nominal.regressor(q + h * v, v + h * a, a)
        behind = self.nominal.regressor(q - h * v, v - h * a, a)
        rate = (ahead - behind) / (2 * h)
        if self.config.payload:
            block = slice(
                N_INERTIAL_PARAMETERS * self.payload_body,
                N_INERTIAL_PARAMETERS * (self.payload_body + 1),
            )
            rate = np.concatenate([rate, rate[:, :, block] @ self.payload_map], axis=2)
        return [self._filter(rate[:, j, :], j)[self.rows] for j in range(self.n)]

    def set_geometry(self, joint: int, ratio: float, phase: float) -> None:
        """Use a balancer geometry on a joint (its basis columns are rebuilt)."""
        self.geometry[joint] = (ratio, phase)
        basis = balancer_basis(self.q[:, joint], ratio, phase)
        self.balancer_basis[joint] = basis
        self.balancer_columns[joint] = self._filter(basis, joint)[self.rows]

    def _balancer_joints(self) -> list[int]:
        setting, joints = self.config.balancer, self.robot.joints
        if setting == 'none':
            return []
        if setting == 'auto':
            nominal = NominalModel(self.robot, self.dataset.target)
            return gravity_loaded_joints(nominal, self.dataset.q, self.config.balancer_min_share)
        names = [name.strip() for name in setting.split(',') if name.strip()]
        unknown = sorted(set(names) - set(joints))
        if unknown:
            raise ConfigError(
                f'identification.balancer: {unknown} are not joints of {list(joints)}'
            )
        return sorted(joints.index(name) for name in names)

    def _filter(self, x: np.ndarray, joint: int | None = None) -> np.ndarray:
        """Columns as the labels meet them: low-passed like them, or as is the study's way."""
        if not self.dataset.is_through_filter:
            return np.asarray(x, dtype=float)
        if joint is None:
            return self.dataset.filter_like_labels(x)
        out = np.zeros_like(x, dtype=float)
        active = np.flatnonzero(np.any(x != 0, axis=0))
        if active.size:
            out[:, active] = self.dataset.filter_like_labels(x[:, active], joint=joint)
        return out

    def _layout(self) -> Layout:
        config, n, joints = self.config, self.n, self.robot.joints
        layout = Layout()
        bodies = len(self.theta0) // N_INERTIAL_PARAMETERS
        names = [f'body {b + 1} {p}' for b in range(bodies) for p in range(N_INERTIAL_PARAMETERS)]
        layout.add('theta', names, self.theta0, config.prior.std(self.theta0))
        if config.payload:
            names = [f'payload {p}' for p in range(N_INERTIAL_PARAMETERS)]
            layout.add('payload', names, np.zeros(N_INERTIAL_PARAMETERS), np.inf)
        if self.motor and config.rotor_inertia:
            rotor = self.robot.drives.rotor_inertia
            std = np.maximum(config.rotor_rel_std * rotor, 1e-6)
            layout.add('rotor', [f'rotor {j}' for j in joints], rotor, std)
        if self.motor and config.label_gain:
            layout.add('gain', [f'gain {j}' for j in joints], np.zeros(n), config.gain_std)
        if self.has_delay:
            layout.add('delay', ['signal delay'], np.zeros(1), np.inf)
        if self.balancer_joints:
            names = [
                f'balancer {joints[j]} c{k}'
                for j in self.balancer_joints
                for k in range(BALANCER_TERMS)
            ]
            layout.add('balancer', names, np.zeros(len(names)), np.inf)
        for law in self.laws:
            layout.add(law, [f'{law} {j}' for j in joints], np.zeros(n), np.inf)
        if config.offsets:
            layout.add('offset', [f'offset {j}' for j in joints], np.zeros(n), np.inf)
        return layout

    @property
    def rigid_block(self) -> slice:
        """The bodies' and the payload's parameters, in the regressor's column order."""
        blocks = self.layout.blocks
        stop = blocks['payload'].stop if 'payload' in blocks else blocks['theta'].stop
        return slice(blocks['theta'].start, stop)

    def theta(self, x: np.ndarray) -> np.ndarray:
        """The bodies' parameters in x, the payload added to its carrying body."""
        theta = x[self.layout.blocks['theta']].copy()
        if 'payload' in self.layout.blocks:
            block = slice(
                N_INERTIAL_PARAMETERS * self.payload_body,
                N_INERTIAL_PARAMETERS * (self.payload_body + 1),
            )
            theta[block] += self.payload_map @ x[self.layout.blocks['payload']]
        return theta

    def balancer_rate(self, j: int) -> np.ndarray:
        """Joint j's filtered balancer basis rate d basis / dq * v on the kept rows, (rows, 3)."""
        ratio, phase = self.geometry[j]
        h = 1e-5
        q = self.q[:, j]
        slope = (balancer_basis(q + h, ratio, phase) - balancer_basis(q - h, ratio, phase)) / (
            2 * h
        )
        key = (j, ratio, phase)
        if key not in self._balancer_rates:
            self._balancer_rates[key] = self._filter(slope * self.v[:, j : j + 1], j)[self.rows]
        return self._balancer_rates[key]

    def balancer_matrix(self, x: np.ndarray) -> np.ndarray:
        """(n, 3) balancer coefficients in x (zero rows for joints without one)."""
        out = np.zeros((self.n, BALANCER_TERMS))
        if 'balancer' in self.layout.blocks:
            values = x[self.layout.blocks['balancer']].reshape(len(self.balancer_joints), -1)
            out[self.balancer_joints] = values
        return out

    def friction(self, x: np.ndarray, stribeck: np.ndarray) -> dict[str, np.ndarray]:
        """Each friction law's filtered column (rows, n); the load from x's RNEA and balancer."""
        tau_link = np.einsum('tjp,p->tj', self.regressor, x[self.rigid_block])
        coefficients = self.balancer_matrix(x)
        for j, basis in self.balancer_basis.items():
            tau_link[:, j] += basis @ coefficients[j]
        columns = friction_columns(
            self.laws, self.v, tau_link, self.config.smoothing_velocity, stribeck
        )
        return {law: self._filter(column)[self.rows] for law, column in columns.items()}

    def design(self, x: np.ndarray, stribeck: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The linearised, weighted system (A, b) around the estimate x."""
        blocks, n, rows = self.layout.blocks, self.n, len(self.rows)
        rigid_block = self.rigid_block
        theta = x[rigid_block]
        rotor = x[blocks['rotor']] if 'rotor' in blocks else np.zeros(n)
        gain = x[blocks['gain']] if 'gain' in blocks else np.zeros(n)
        friction = self.friction(x, stribeck)
        a = np.zeros((n, rows, len(self.layout)))
        b = np.empty((n, rows))
        for j in range(n):
            rigid = self.filtered_regressor[j]
            a[j, :, rigid_block] = (1.0 + gain[j]) * rigid
            model = rigid @ theta
            if 'rotor' in blocks:
                assert self.rotor_column is not None
                a[j, :, blocks['rotor'].start + j] = (1.0 + gain[j]) * self.rotor_column[:, j]
                model = model + rotor[j] * self.rotor_column[:, j]
            b[j] = self.label[:, j]
            if 'gain' in blocks:
                # (1 + g)(Y theta) ~ (1 + g0) Y theta + (g - g0) Y theta0: bilinear, linearised.
                a[j, :, blocks['gain'].start + j] = model
                b[j] += gain[j] * model
            if j in self.balancer_columns:
                first = blocks['balancer'].start + self.balancer_joints.index(j) * BALANCER_TERMS
                a[j, :, first : first + BALANCER_TERMS] = self.balancer_columns[j]
            if 'delay' in blocks:
                # tau(t - d) ~ tau - d * rate: the rate of the current estimate's link torque.
                assert self.filtered_rate is not None
                rate = self.filtered_rate[j] @ x[self.rigid_block]
                if j in self.balancer_columns:
                    rate = rate + self.balancer_rate(j) @ self.balancer_matrix(x)[j]
                a[j, :, blocks['delay'].start] = -rate
            for law, column in friction.items():
                a[j, :, blocks[law].start + j] = column[:, j]
            if 'offset' in blocks:
                a[j, :, blocks['offset'].start + j] = 1.0
            a[j] *= self.row_weight[j]
            b[j] *= self.row_weight[j]
        return a.reshape(n * rows, -1), b.reshape(-1)


def choose_stribeck(problem: Problem, x: np.ndarray, stribeck: np.ndarray) -> np.ndarray:
    """Per joint, the candidate Stribeck velocity whose refit leaves the least residual.

    Only the joint's own drive columns are refitted (ordinary least squares), the rest held.
    """
    if 'stribeck' not in problem.laws:
        return stribeck
    blocks, n, rows = problem.layout.blocks, problem.n, len(problem.rows)
    best = stribeck.copy()
    a, b = problem.design(x, stribeck)
    a, b = a.reshape(n, rows, -1), b.reshape(n, rows)
    local = [blocks[name].start for name in ('rotor', 'gain', *problem.laws, 'offset')
             if name in blocks]  # fmt: skip
    for j in range(n):
        columns = [k + j for k in local]
        held = np.delete(np.arange(a.shape[2]), columns)
        target = b[j] - a[j][:, held] @ x[held]
        errors = []
        for vs in problem.config.stribeck_velocities:
            trial = stribeck.copy()
            trial[j] = vs
            column = problem.friction(x, trial)['stribeck'][:, j]
            design = a[j][:, columns].copy()
            design[:, columns.index(blocks['stribeck'].start + j)] = column * problem.row_weight[j]
            coefficients, *_ = np.linalg.lstsq(design, target, rcond=None)
            errors.append(float(np.sum((design @ coefficients - target) ** 2)))
        best[j] = problem.config.stribeck_velocities[int(np.argmin(errors))]
    return best


def joint_system(
    problem: Problem, x: np.ndarray, stribeck: np.ndarray, j: int, local: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Joint j's rows: its local columns (weighted) and the target with the rest held at x."""
    a, b = problem.design(x, stribeck)
    rows = len(problem.rows)
    a, b = a.reshape(problem.n, rows, -1)[j], b.reshape(problem.n, rows)[j]
    held = np.delete(np.arange(a.shape[1]), local)
    return a[:, local], b - a[:, held] @ x[held]


@dataclass(eq=False)
class NormalEquations:
    """The regularised normal equations of (A, b), columns scaled to unit norm."""

    a: np.ndarray
    b: np.ndarray
    scale: np.ndarray
    gram: np.ndarray
    right: np.ndarray
    precision: np.ndarray
    mean: np.ndarray

    @classmethod
    def of(cls, a: np.ndarray, b: np.ndarray, layout: Layout) -> NormalEquations:
        """The equations of the system (a, b) with the layout's priors."""
        mean = np.asarray(layout.prior_mean)
        std = np.asarray(layout.prior_std)
        precision = np.where(np.isfinite(std), 1.0 / std**2, 0.0)
        scale = np.linalg.norm(a, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        scaled = a / scale
        # In the scaled unknowns u = x * scale: A x = (A / scale) u.
        right = scaled.T @ b + precision * mean / scale
        return cls(scaled, b, scale, scaled.T @ scaled, right, precision, mean)

    def misfit_with(self, columns: np.ndarray, rows: slice, new: np.ndarray) -> float:
        """The minimised objective with ``columns`` replaced by ``new`` on ``rows``.

        ``new`` is zero outside ``rows``; the objective is up to the constant b^T b.
        """
        new = new / self.scale[columns]
        g, r = self.gram.copy(), self.right.copy()
        cross = self.a[rows].T @ new
        g[:, columns] = cross
        g[columns, :] = cross.T
        g[np.ix_(columns, columns)] = new.T @ new
        r[columns] = new.T @ self.b[rows]
        regular = g + np.diag(self.precision / self.scale**2) + 1e-12 * np.eye(len(g))
        u = np.linalg.solve(regular, r)
        prior = np.sum(self.precision * (u / self.scale - self.mean) ** 2)
        return float(u @ g @ u - 2 * u @ r + prior)


def choose_balancers(problem: Problem, x: np.ndarray, stribeck: np.ndarray) -> None:
    """Per balancer joint, the geometry whose refit leaves the least (regularised) misfit.

    Every parameter is refitted for each candidate geometry (the priors included, the
    constraints left out), because a balancer trades against the first moment of the link it
    holds: a grid of ratios and phases, then the ratio refined. The normal equations are
    updated for the joint's three balancer columns only, so a candidate costs milliseconds.
    """
    from scipy import optimize

    layout, config = problem.layout, problem.config
    for j in problem.balancer_joints:
        equations = NormalEquations.of(*problem.design(x, stribeck), layout)
        rows = slice(j * len(problem.rows), (j + 1) * len(problem.rows))
        first = layout.blocks['balancer'].start + problem.balancer_joints.index(j) * BALANCER_TERMS
        columns = np.arange(first, first + BALANCER_TERMS)

        def misfit(
            ratio: float,
            phase: float,
            *,
            j: int = j,
            rows: slice = rows,
            columns: np.ndarray = columns,
            equations: NormalEquations = equations,
        ) -> float:
            problem.set_geometry(j, ratio, phase)
            new = problem.balancer_columns[j] * problem.row_weight[j]
            return equations.misfit_with(columns, rows, new)

        grid = [(r, p) for r in config.balancer_ratios for p in config.balancer_phases]
        start = min(grid, key=lambda g: misfit(*g))
        # Refined together: an encoder zero error shifts the phase by milliradians.
        best = optimize.minimize(
            lambda g, misfit=misfit: misfit(float(np.clip(g[0], 0.05, 0.98)), float(g[1])),
            np.array(start),
            method='Nelder-Mead',
            options={
                'xatol': 1e-4,
                'fatol': 1e-9,
                'initial_simplex': [
                    start,
                    (start[0] + 0.05, start[1]),
                    (start[0], start[1] + 0.05),
                ],
            },
        )
        problem.set_geometry(j, float(np.clip(best.x[0], 0.05, 0.98)), float(best.x[1]))
