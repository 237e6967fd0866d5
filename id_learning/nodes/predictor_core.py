"""The predictor node's core from its parameters: robot, threads, artifact, adaptation, warm-up.

Apart from the node (``nodes.predictor``), which loads nothing: ``make_predictor`` reads the
parameters, builds the core here and makes the node around it.
"""

from __future__ import annotations

from id_learning.errors import ConfigError
from id_learning.nodes.params import PredictorNodeConfig, guard_config, resolve_robot_config
from id_learning.predictor import FeedForwardPredictor, configure_inference_threads
from id_learning.predictor.adaptation import AdaptationConfig, AdaptationLoop
from id_learning.robot.config import RobotConfig, load_robot_config

__all__ = ['adaptation_loop', 'build_core']


def build_core(config: PredictorNodeConfig) -> tuple[FeedForwardPredictor, RobotConfig]:
    """The node's core from its parameters: robot, threads, artifact, adaptation, warmed up.

    Raises:
        ConfigError, CheckpointError, RobotModelError: the robot config or the artifact is
            unusable, or adaptation is asked of a model that does not predict tau_u.
    """
    robot = load_robot_config(resolve_robot_config(config.robot_config))
    configure_inference_threads(config.torch_threads)
    core = FeedForwardPredictor.from_artifact(
        config.artifact,
        robot,
        guard_config(config, robot),
        inference=config.inference,
        fallback_artifact=config.fallback_artifact or None,
    )
    if config.adaptation != 'off':
        core.adaptation = adaptation_loop(config, robot, core)
    core.warm_up()
    return core, robot


def adaptation_loop(
    config: PredictorNodeConfig, robot: RobotConfig, core: FeedForwardPredictor
) -> AdaptationLoop:
    """The RLS adaptation of a motor-target model.

    Raises:
        ConfigError: the model predicts a measured joint torque, which currents do not give.
    """
    target = core.target
    if target != 'motor':
        raise ConfigError(
            f'adaptation rls learns tau_u from motor currents; the {core.model.kind} model '
            f'predicts the {target} target: set adaptation off'
        )
    settings = AdaptationConfig(time_constant_s=config.adaptation_time_constant_s)
    loop = AdaptationLoop.for_robot(
        robot, core.joint_names, settings, inertia=config.adaptation == 'rls_inertia'
    )
    loop.reference_source = config.input_topic
    return loop
