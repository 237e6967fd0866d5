"""The identification's least-squares problem: its layout and its rows.

``Problem`` stacks one recording's training part into a weighted, linearised system around the
current estimate (see ``physics.identification`` for the model and the method);
``physics.identification_search`` picks its nonlinear settings.
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from id_learning.dataset.preprocess import Dataset
from id_learning.dataset.statistics import estimate_noise, integrated_autocorrelation
from id_learning.errors import ConfigError, DatasetError
from id_learning.physics.balancer import (
    BALANCER_PHASES,
    BALANCER_RATIOS,
    BALANCER_TERMS,
    balancer_basis,
)
from id_learning.physics.base_parameters import CadPrior
from id_learning.physics.effects import FRICTION_LAWS, friction_law
from id_learning.physics.identified import RATE_STEP_S, friction_columns
from id_learning.physics.inertial import frame_parameter_map
from id_learning.physics.nominal import NominalModel
from id_learning.physics.rigid_body import N_INERTIAL_PARAMETERS, RigidBodyDynamics
from id_learning.physics.terms import gravity_loaded_joints
from id_learning.robot.config import RobotConfig
from id_learning.robot.drives import rotor_basis

__all__ = ['COGGING_PERIODS', 'PINNED_STD', 'IdentificationConfig', 'Layout', 'Problem']

#: Candidate cogging periods per motor turn: every one up to 12, and the diagnosis's higher ones.
COGGING_PERIODS = (*range(1, 13), 18, 24, 36)


@dataclass(frozen=True)
class IdentificationConfig:
    """What the identification estimates and how strongly it trusts the CAD model.

    Attributes:
        friction: friction laws per joint. Joint-torque labels carry the friction on the link
            side of the sensor (a Panda's bearings and output stage), motor labels all of it.
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
        confirm: judge what the CAD model does not hold (balancers, a payload, a body leaving
            its prior's 95 % range) on the training part's held-out tail, and hold what it does
            not confirm at its prior (``physics.confirmation``).
        significance: the level at which the held-out blocks confirm a claim (Holm-corrected).
        cogging: after the fit through the filter, find each joint's motor cogging (a ripple
            s sin(p N q) + c cos(p N q), far above the label filter's band) on the training
            part's unfiltered labels (``physics.cogging``); motor labels only. False: none.
        cogging_periods: candidate periods p per motor turn; at most one is kept per joint.
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
    confirm: bool = True
    significance: float = 0.01
    cogging: bool = True
    cogging_periods: tuple[int, ...] = COGGING_PERIODS

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
        if not 0 < self.significance < 0.5:
            raise ConfigError(
                f'identification.significance must lie in (0, 0.5), got {self.significance}'
            )
        periods = self.cogging_periods
        if not periods or not all(isinstance(p, int) and p >= 1 for p in periods):
            raise ConfigError(
                'identification.cogging_periods: need whole numbers of periods per motor turn '
                f'>= 1, got {periods!r}'
            )
        for key in ('smoothing_velocity', 'rotor_rel_std', 'gain_std'):
            if not getattr(self, key) > 0:
                raise ConfigError(f'identification.{key} must be > 0, got {getattr(self, key)}')


#: The prior std of a parameter held at its prior mean (``Layout.pin``): the solver scales each
#: unknown by its std, so the parameter cannot move while the problem stays well conditioned.
PINNED_STD = 1e-12


@dataclass(eq=False)
class Layout:
    """Where each parameter sits in the stacked vector x, with its prior."""

    names: list[str] = field(default_factory=list)
    prior_mean: list[float] = field(default_factory=list)
    prior_std: list[float] = field(default_factory=list)  # inf: no prior
    blocks: dict[str, slice] = field(default_factory=dict)

    @property
    def index(self) -> dict[str, int]:
        """Each parameter's position in x."""
        return {name: k for k, name in enumerate(self.names)}

    def copy(self) -> Layout:
        """An independent copy (priors and pins may then change)."""
        return Layout(
            list(self.names), list(self.prior_mean), list(self.prior_std), dict(self.blocks)
        )

    def pin(self, names: Sequence[str]) -> None:
        """Hold the parameters ``names`` at their prior mean (a prior of zero width)."""
        index = self.index
        for name in names:
            self.prior_std[index[name]] = PINNED_STD

    def pinned_names(self) -> list[str]:
        """The parameters held at their prior mean."""
        return [n for n, std in zip(self.names, self.prior_std, strict=True) if std == PINNED_STD]

    def transfer(self, x: np.ndarray, other: Layout) -> np.ndarray:
        """The estimate ``x`` of ``other``'s layout in this one; the rest at the prior mean."""
        out = np.where(np.isfinite(self.prior_mean), self.prior_mean, 0.0)
        index = other.index
        for k, name in enumerate(self.names):
            if name in index:
                out[k] = x[index[name]]
        return out

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
        self.laws = tuple(law for law in FRICTION_LAWS if law in config.friction)
        #: The law with a hump velocity per joint (Stribeck), if the model has one.
        self.hump_law = next((law for law in self.laws if friction_law(law).hump), None)
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
        self.spacing = spacing
        self.noise_correlation = tau
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
        self.rotor_column = self._filter(rotor_basis(a, gear))[self.rows] if self.motor else None
        self.label = dataset.tau[self.rows]
        self.balancer_joints = self._balancer_joints()
        self.q = q
        #: Per balancer joint, its geometry (ratio, phase), and its basis (N, 3), unfiltered, and
        #: filtered on the kept rows.
        self.geometry: dict[int, tuple[float, float]] = {}
        self._balancer_rates: dict[tuple[int, float, float], np.ndarray] = {}
        self.balancer_basis: dict[int, np.ndarray] = {}
        self.balancer_columns: dict[int, np.ndarray] = {}
        #: Filtered friction columns (N,) that do not change with the estimate, by (law, joint,
        #: Stribeck velocity); the same for every subset of the rows.
        self._filtered_friction: dict[tuple[str, int, float], np.ndarray] = {}
        for j in self.balancer_joints:
            self.set_geometry(j, float(np.median(config.balancer_ratios)), 0.0)
        self.layout = self._layout()

    def subset(self, keep: np.ndarray) -> Problem:
        """The same problem on some of its kept rows (``keep``: positions into ``rows``)."""
        out = copy.copy(self)
        out.rows = self.rows[keep]
        out.filtered_regressor = [r[keep] for r in self.filtered_regressor]
        if self.filtered_rate is not None:
            out.filtered_rate = [r[keep] for r in self.filtered_rate]
        if self.rotor_column is not None:
            out.rotor_column = self.rotor_column[keep]
        out.label = self.label[keep]
        out.geometry = dict(self.geometry)
        out.balancer_basis = dict(self.balancer_basis)
        out.balancer_columns = {j: c[keep] for j, c in self.balancer_columns.items()}
        out._balancer_rates = {}
        return out

    def without_balancers(self, joints: Sequence[int]) -> Problem:
        """The same problem without the balancers on ``joints`` (its layout rebuilt)."""
        out = copy.copy(self)
        out.balancer_joints = [j for j in self.balancer_joints if j not in joints]
        for name in ('geometry', 'balancer_basis', 'balancer_columns'):
            kept = {j: value for j, value in getattr(self, name).items() if j not in joints}
            setattr(out, name, kept)
        out._balancer_rates = {}
        out.layout = out._layout()
        out.layout.pin([n for n in self.layout.pinned_names() if n in out.layout.index])
        return out

    def pinned(self, names: Sequence[str]) -> Problem:
        """The same problem with the parameters ``names`` held at their prior mean."""
        out = copy.copy(self)
        out.layout = self.layout.copy()
        out.layout.pin(names)
        return out

    def reweight(self, residual: np.ndarray) -> None:
        """Weigh each joint's rows by what the model leaves there, not by the label noise alone.

        ``residual`` (n, rows): a fit's weighted residual on the kept rows. Where the model
        cannot follow the labels (a form it lacks, on a real robot), its residual is larger and
        correlated for longer than the noise: the data then hold fewer independent samples and
        weigh less against the CAD prior, so a body does not take a wrong mass to absorb it.
        Where the model reaches the noise floor the weights stay the noise's.
        """
        raw = residual / self.row_weight[:, None]
        rms = np.sqrt(np.mean(raw**2, axis=1))
        correlation = self.noise_correlation.astype(float).copy()
        if not self.dataset.is_shuffled:
            for j in range(self.n):
                correlation[j] = max(
                    correlation[j], integrated_autocorrelation(raw[j]) * self.step
                )
        sigma = np.maximum(self.noise_std, rms)
        self.row_weight = np.sqrt(self.spacing / correlation) / sigma

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

    @functools.cached_property
    def nominal_gravity(self) -> np.ndarray:
        """(N, n) the URDF's gravity torque along the recording [N*m]."""
        return self.nominal.gravity(self.q)

    def kept_columns(self, x: np.ndarray, joint: int) -> np.ndarray:
        """Columns (N, k) of one joint as its label meets them, on the kept rows."""
        out: np.ndarray = self._filter(x, joint)[self.rows]
        return out

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

    def friction(
        self, x: np.ndarray, stribeck: np.ndarray, laws: tuple[str, ...] | None = None
    ) -> dict[str, np.ndarray]:
        """Each friction law's filtered column (rows, n); the load from x's RNEA and balancer.

        Only the load-dependent law changes with x, and a Stribeck column with its joint's
        velocity: the others are filtered once (``_filtered_friction``, shared by subsets).
        """
        out = {}
        for law in laws or self.laws:
            if friction_law(law).reads_link_torque:
                tau_link = np.einsum('tjp,p->tj', self.regressor, x[self.rigid_block])
                coefficients = self.balancer_matrix(x)
                for j, basis in self.balancer_basis.items():
                    tau_link[:, j] += basis @ coefficients[j]
                (column,) = friction_columns(
                    (law,), self.v, tau_link, self.config.smoothing_velocity, stribeck
                ).values()
                out[law] = self._filter(column)[self.rows]
            elif law == self.hump_law:
                out[law] = np.stack(
                    [self._fixed_friction(law, j, float(stribeck[j])) for j in range(self.n)],
                    axis=1,
                )[self.rows]
            else:
                out[law] = np.stack(
                    [self._fixed_friction(law, j, 0.0) for j in range(self.n)], axis=1
                )[self.rows]
        return out

    def _fixed_friction(self, law: str, joint: int, velocity: float) -> np.ndarray:
        """One joint's filtered column (N,) of a law that does not change with the estimate."""
        key = (law, joint, velocity)
        if key not in self._filtered_friction:
            stribeck = np.full(self.n, velocity if velocity > 0 else 1.0)
            (column,) = friction_columns(
                (law,), self.v[:, joint : joint + 1], np.zeros((len(self.v), 1)),
                self.config.smoothing_velocity, stribeck[joint : joint + 1],
            ).values()  # fmt: skip
            self._filtered_friction[key] = self._filter(column, joint)[:, 0]
        return self._filtered_friction[key]

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
