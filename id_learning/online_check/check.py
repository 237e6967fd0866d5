"""Online check: replay an excerpt of a bag's test part through the predictor node, in real time.

``online_check`` starts the ``replay`` and ``predictor`` nodes as separate processes, listens to
the reference and tau_u in this process over DDS, and compares what the predictor published with
the offline prediction of the same artifact on the same samples, both against the label.

The samples: the test part of the bag exactly as the trainer splits it (``load_datasets`` with the
preprocessing stored in the artifact, then ``segment_rows(dataset, 'test')``), from its start,
``seconds`` long (clipped to the test part). The offline inputs are that dataset's controller
inputs (the artifact's input definition: recorded q, v smoothed far above the motion's band, a by
central differences); the replay builds its reference with the same velocity smoothing. The
offline prediction runs on the excerpt's rows, so a sequence model starts its window at the
excerpt as the node does.

Against the label: tau_u is the torque the drive needs now, the label a low-passed torque; so
both the online and the offline excerpt are put into the model's offline torque along the whole
recording, which is then low-passed like the labels, and compared with the label on the excerpt
(the trainer's "through the filter" figure, restricted to the excerpt).

Why online and offline may differ: the predictor gets the replay's reference, which the replay
rebuilds from the recorded joint states with the same smoothing, but filtered over the played
span plus ``REFERENCE_PAD_S`` (10 s) on either side (not over the whole recording) and
differentiated over the bag's stamps as recorded (not snapped to the grid). The filter's edge
transients therefore leave small differences in q, v and a, reported as ``max_input_diff``; on
top, tau_u is clamped to the torque limits, and a sample the node's input queue dropped has no
tau_u. To tell these input differences from an error in the node, the artifact is also run
offline on exactly the references the predictor received: ``max_abs_node_error_nm`` must be at
floating-point level (float32 rounding for the networks, batched against one sample at a time; 0
for a float64 model such as RNEA+LQ). The predictor runs with ``out_of_range: warn`` here, so that
it serves the model itself everywhere; samples beyond the training range are counted.

Isolation: both nodes run in a private namespace (also their /diagnostics, and the replayed joint
states are remapped into it; no /clock), so the check cannot feed a live system that shares the
DDS domain. The domain is ``ROS_DOMAIN_ID`` from the environment unless given;
``ROS_AUTOMATIC_DISCOVERY_RANGE`` defaults to LOCALHOST.

The check is split along its steps: ``plan`` (the artifact's setup and the excerpt, offline),
``ros`` (the node processes and the replay run, watched through ``nodes.listener``), ``scoring``
(the comparison) and ``result`` (the result); this module holds the public entry point that runs
them in order. It sits beside the ``demo`` command that runs it, above the nodes it starts: the
nodes themselves import neither the trainer nor the evaluation.
"""

from __future__ import annotations

import importlib.util
import json
import os
import tempfile
import time
from pathlib import Path

from id_learning.errors import ConfigError
from id_learning.nodes.process import node_processes
from id_learning.online_check.plan import load_setup, plan_excerpt
from id_learning.online_check.result import OnlineCheckError, OnlineCheckResult
from id_learning.online_check.ros import replay_and_collect, start_predictor
from id_learning.online_check.scoring import score
from id_learning.training.run_folder import MODELS_DIR, check_run_model, refuse_incomplete_run

__all__ = ['OnlineCheckError', 'OnlineCheckResult', 'has_ros', 'online_check']


def online_check(
    bag: Path,
    robot_config_path: Path,
    artifact: Path,
    *,
    seconds: float = 30.0,
    out: Path | None = None,
    domain_id: int | None = None,
    input_depth: int | None = None,
    max_age_s: float | None = None,
    progress: bool = True,
) -> OnlineCheckResult:
    """Replay ``seconds`` of the bag's test part through the predictor node and compare offline.

    Args:
        bag: the recording (the bag contract); its test part is the trainer's.
        robot_config_path: robot config YAML the artifact was trained for.
        artifact: model artifact folder (any kind).
        seconds: length of the excerpt [s], from the start of the test part; clipped to it.
        out: also write the result as JSON here.
        domain_id: ROS domain; None: ``ROS_DOMAIN_ID`` from the environment (else 0).
        input_depth: the predictor's reference queue depth; None: the node's default, with
            which a machine stall longer than that many cycles drops samples (reported as
            missing), as it would in production. A depth of the excerpt's length loses none.
        max_age_s: the predictor's ``max_age_s``; None: the node's default, with which a stall of
            the machine longer than that refuses samples as too old (reported); 0: no time checks.
        progress: print what is happening.

    Returns:
        The measured result; ``summary()`` gives the text.

    Raises:
        CheckpointError: the artifact is invalid or not for this robot, or it belongs to a run
            that is incomplete (a ``train`` killed or still running).
        BagError, DatasetError: the bag is unusable or the excerpt is too short.
        OnlineCheckError: rclpy is missing, a node failed to start or finish (with the tail of
            its log), or no tau_u came back.
        ConfigError: ``seconds`` or the domain id is out of range.
    """
    began = time.monotonic()
    if not has_ros():
        raise OnlineCheckError(
            'rclpy (ROS 2 Jazzy) is not installed: the online check needs the ROS nodes; see '
            'README, Quick start'
        )
    if not seconds > 0:
        raise ConfigError(f'seconds must be > 0, got {seconds}')
    domain = _domain(domain_id)
    if Path(artifact).parent.name == MODELS_DIR:  # a model of a run: the run must be complete
        refuse_incomplete_run(Path(artifact).parent.parent)
        check_run_model(Path(artifact))  # and the model the one it saved
    notes: list[str] = []
    setup = load_setup(Path(bag), Path(robot_config_path), Path(artifact), notes)
    namespace = f'/online_check_{os.getpid()}'
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # before rclpy.init

    def say(text: str) -> None:
        if progress:
            print(f'online check: {text}', flush=True)

    with (
        tempfile.TemporaryDirectory(prefix='online_check_') as tmp,
        node_processes(Path(tmp), domain) as start,
    ):
        say(f'starting the predictor ({setup.kind}, domain {domain}, namespace {namespace})')
        predictor = start_predictor(
            start, setup, namespace, seconds=seconds, input_depth=input_depth, max_age_s=max_age_s
        )
        # While the node imports torch: the trainer's preprocessing and split of this bag.
        say(f'preprocessing {setup.bag} as the trainer does ({setup.preprocess.target} labels)')
        excerpt = plan_excerpt(setup, seconds, notes)
        collected = replay_and_collect(
            start, predictor, setup, excerpt, domain=domain, namespace=namespace, say=say
        )
    # The comparison after the nodes are stopped: nothing competes for the cores.
    result = score(setup, excerpt, collected, notes, began)
    if out is not None:
        _write(result, Path(out))
    return result


def has_ros() -> bool:
    """Whether rclpy (ROS 2 Jazzy) can be imported, i.e. the online check can run here."""
    return importlib.util.find_spec('rclpy') is not None


def _domain(domain_id: int | None) -> int:
    if domain_id is None:
        text = os.environ.get('ROS_DOMAIN_ID', '').strip() or '0'
        try:
            domain_id = int(text)
        except ValueError:
            raise ConfigError(f'ROS_DOMAIN_ID must be an integer, got {text!r}') from None
    if not 0 <= domain_id <= 232:
        raise ConfigError(f'ROS domain id must be in [0, 232], got {domain_id}')
    return domain_id


def _write(result: OnlineCheckResult, out: Path) -> None:
    """The result as JSON at ``out`` (folders made)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result.to_dict(), indent=1) + '\n', encoding='utf-8')
