"""The physics prior a network falls back to outside its training envelope.

A network extrapolates where it has seen no data; the rigid-body model does not. Under
``out_of_range: fallback`` the predictor publishes ``(1 - w) tau_network + w tau_physics`` with
``w`` rising smoothly from 0 at the edge of the training range to 1 at the edge of its margin
(``range_margin`` half ranges beyond it), so the output has no step where the input crosses it.

The prior, in order of preference: a physics artifact given to the predictor (an identified
``rnea_id``, ``rnea_effects`` or ``rnea_lq`` of the same robot and target); the identified
``rnea_id`` that ``train`` wrote beside the model in the same run; the model's own physics part
(``rnea_mlp``, ``rnea_id_mlp``, ``rnea_effects_mlp``: their h is the network; ``delan_id``,
``lnn_mlp_id``: their Lagrangian residual is); the nominal model
(URDF rigid body plus datasheet rotor inertia for motor torques). Friction is the largest term
of a motor torque, and only an identified prior has it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from id_learning.errors import CheckpointError, IdLearningError
from id_learning.models.base import InverseDynamicsModel, SamplePredictor
from id_learning.models.torch_model import TorchModel
from id_learning.physics.nominal import NominalModel
from id_learning.robot.config import RobotConfig

__all__ = ['PhysicsFallback', 'blend_weight', 'is_network', 'physics_fallback']


@dataclass(frozen=True, eq=False)
class PhysicsFallback:
    """A one-sample physics torque and where it comes from (for logs and diagnostics)."""

    predict_one: SamplePredictor
    source: str


def is_network(model: InverseDynamicsModel) -> bool:
    """Whether any part of the model is a learned network (it can extrapolate wildly)."""
    return isinstance(model, TorchModel)


def blend_weight(excess: float, margin: float) -> float:
    """The physics share w for an input ``excess`` half ranges beyond the training range.

    0 inside the range, 1 from ``margin`` half ranges beyond it, a smoothstep between (zero slope
    at both ends); with no margin, a switch at the range's edge.
    """
    if excess <= 0.0:
        return 0.0
    if excess >= margin:
        return 1.0
    x = excess / margin
    return x * x * (3.0 - 2.0 * x)


def physics_fallback(
    model: InverseDynamicsModel,
    robot: RobotConfig,
    target: str,
    artifact: Path | str | None = None,
    *,
    beside: Path | str | None = None,
) -> PhysicsFallback:
    """The physics prior of a model (module docstring), for a robot and label target.

    Args:
        model: the served model (its joint order is the robot's).
        robot: the robot config.
        target: 'motor' or 'joint': what the model's torque is (the prior must be the same).
        artifact: a physics artifact folder to use, or None.
        beside: the served model's artifact folder: an ``rnea_id`` of the same target next to
            it (a run's models/ folder) is the prior when ``artifact`` is None.

    Raises:
        CheckpointError: ``artifact`` is unreadable, of another robot, a network, or fitted on
            another target.
    """
    if artifact:
        return _physics_artifact(Path(artifact), robot, target)
    sibling = None if beside is None else Path(beside).parent / 'rnea_id'
    if sibling is not None and sibling.resolve() != Path(beside or '').resolve():
        try:
            return _physics_artifact(sibling, robot, target)
        except (IdLearningError, OSError, ValueError):
            pass  # none there, or not one for this model: the next prior
    own = getattr(model, 'physics_sample_predictor', None)
    if own is not None:
        return PhysicsFallback(own(), f"{model.kind}'s own physics part")
    label = 'URDF + datasheet rotor inertia' if target == 'motor' else 'URDF'
    nominal = NominalModel(robot, target).sample_function()
    return PhysicsFallback(nominal, f'nominal model ({label})')


def _physics_artifact(path: Path, robot: RobotConfig, target: str) -> PhysicsFallback:
    from id_learning.models.artifact import METADATA_FILE, artifact_target, read_metadata
    from id_learning.models.registry import load_model

    prior = load_model(path, robot).for_the_drive()
    if is_network(prior):
        raise CheckpointError(
            f'{path}: a {prior.kind} model is a network, not a physics prior; give an '
            'rnea_id, rnea_effects or rnea_lq artifact'
        )
    prior_target = artifact_target(read_metadata(path / METADATA_FILE))
    if prior_target != target:
        raise CheckpointError(
            f'{path}: fitted on {prior_target} torques, the served model on {target} torques'
        )
    return PhysicsFallback(prior.sample_predictor(), f'{prior.kind} artifact {path}')
