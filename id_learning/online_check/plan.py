"""The online check's preparation: the artifact's setup and the excerpt of the bag to replay.

Everything here is offline work without rclpy: loading the artifact and the preprocessing it was
trained with, the velocity smoothing the replay must reproduce, the trainer's test part of the
bag, the excerpt within it, the offline prediction on it and the replay's window on the bag.
``online_check`` runs it while the predictor node starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from id_learning.errors import DatasetError
from id_learning.online_check.result import NS_PER_S

__all__ = ['CheckSetup', 'Excerpt', 'load_setup', 'plan_excerpt']


@dataclass(frozen=True, eq=False)
class CheckSetup:
    """What is checked: the bag, the artifact and its model, and how the replay must preprocess.

    Attributes:
        bag, artifact, robot_config_path: the inputs of the check.
        robot: the loaded robot config.
        model: the loaded artifact.
        metadata: the artifact's model.json.
        preprocess: the artifact's ``PreprocessConfig`` (the default where it stores none).
        period_ns: the IPO period [ns].
        smoothing_hz: the replay's velocity smoothing cut-off (0: the robot config's).
    """

    bag: Path
    artifact: Path
    robot_config_path: Path
    robot: Any
    model: Any
    metadata: dict[str, Any]
    preprocess: Any
    period_ns: int
    smoothing_hz: float

    @property
    def kind(self) -> str:
        """The artifact's model kind."""
        out: str = self.model.kind
        return out

    @property
    def joints(self) -> tuple[str, ...]:
        """The model's joint names, the order of every array of the check."""
        return tuple(self.model.joint_names)


def load_setup(bag: Path, robot_config_path: Path, artifact: Path, notes: list[str]) -> CheckSetup:
    """Load the robot config and the artifact; append what the reader should know to ``notes``.

    Raises:
        CheckpointError: the artifact is invalid or not for this robot.
    """
    from id_learning.dataset.preprocess import PreprocessConfig
    from id_learning.models.artifact import METADATA_FILE, read_metadata
    from id_learning.models.registry import load_model
    from id_learning.robot.config import load_robot_config
    from id_learning.training.trainer import preprocess_from_dict

    robot = load_robot_config(robot_config_path)
    model = load_model(artifact, robot).for_the_drive()
    metadata = read_metadata(artifact / METADATA_FILE)
    if metadata.get('preprocessing'):
        preprocess = preprocess_from_dict(metadata['preprocessing'])
    else:
        preprocess = PreprocessConfig()
        notes.append('the artifact stores no preprocessing: the default (motor target) is used')
    smoothing = np.asarray(
        preprocess.input_smoothing_hz
        if preprocess.input_smoothing_hz is not None
        else robot.input_smoothing_hz
    )
    # The replay takes one smoothing cut-off for every joint (0: the robot config's).
    smoothing_hz = float(smoothing[0]) if np.all(smoothing == smoothing[0]) else 0.0
    if not smoothing_hz and not np.array_equal(smoothing, robot.input_smoothing_hz):
        notes.append(
            f'the artifact smooths velocities at {smoothing.tolist()} Hz per joint; the replay '
            f"takes one value, so it uses the robot config's {robot.input_smoothing_hz.tolist()}"
        )
    return CheckSetup(
        bag=bag,
        artifact=artifact,
        robot_config_path=robot_config_path,
        robot=robot,
        model=model,
        metadata=metadata,
        preprocess=preprocess,
        period_ns=round(robot.ipo_period_s * NS_PER_S),
        smoothing_hz=smoothing_hz,
    )


@dataclass(frozen=True, eq=False)
class Excerpt:
    """The excerpt: dataset rows [test_start, stop) of the test part [test_start, test_stop).

    Attributes:
        dataset: the bag preprocessed as the trainer does.
        test_start, test_stop: the test part's rows.
        stop: the excerpt's end row (exclusive).
        is_clipped: the test part is shorter than the requested excerpt.
        along: the model's offline torque along the whole recording (controller inputs).
        offline: the model's offline prediction on the excerpt's rows.
        start_offset_s, duration_s: the replay's window on the bag [s].
        excerpt_start_s, excerpt_s: start (from the bag's first sample) and length [s].
    """

    dataset: Any
    test_start: int
    test_stop: int
    stop: int
    is_clipped: bool
    along: np.ndarray
    offline: np.ndarray
    start_offset_s: float
    duration_s: float
    excerpt_start_s: float
    excerpt_s: float

    @property
    def n_samples(self) -> int:
        """Samples in the excerpt."""
        return self.stop - self.test_start


def plan_excerpt(setup: CheckSetup, seconds: float, notes: list[str]) -> Excerpt:
    """The bag preprocessed and split as the trainer does; ``seconds`` from the test part's start.

    Raises:
        BagError, DatasetError: the bag is unusable or the test part has under 3 samples.
    """
    from id_learning.evaluation.scoring import predict_along
    from id_learning.training.trainer import bag_sha256, load_datasets, segment_rows

    bag, robot, model, period_ns = setup.bag, setup.robot, setup.model, setup.period_ns
    segments = load_datasets([bag], robot, setup.preprocess, progress=False)
    dataset = segments[0]
    if len(segments) > 1:
        notes.append(
            f'the bag holds {len(segments)} segments: replayed the test part of the first one'
        )
    if dataset.is_shuffled:  # its test samples are scattered: replay the last stretch in time
        n_rows = len(dataset.tau)
        test_start, test_stop = round(setup.preprocess.train_fraction * n_rows), n_rows
    else:
        test_start, test_stop = segment_rows(dataset, 'test')[0]
    n_wanted = round(seconds * NS_PER_S / period_ns)
    stop = min(test_start + n_wanted, test_stop)
    if stop - test_start < 3:
        raise DatasetError(
            f'{bag}: the test part has {test_stop - test_start} samples; the online check '
            'needs at least 3'
        )
    is_clipped = stop - test_start < n_wanted
    if is_clipped:
        notes.append(
            f'the test part lasts {(test_stop - test_start) * robot.ipo_period_s:.1f} s: '
            f'replayed all of it instead of {seconds:g} s'
        )
    trained_on = {
        entry.get('sha256') for entry in setup.metadata.get('training_data', {}).get('bags', [])
    }
    if dataset.is_shuffled and bag_sha256(bag) in trained_on:
        notes.append(
            'the artifact was fitted on a shuffled split: the replayed stretch (the last '
            f'{1 - setup.preprocess.train_fraction:.0%} in time) holds training samples too'
        )
    if bag_sha256(bag) not in trained_on:
        notes.append(
            'the bag is not one of the artifact\'s training bags: its "test part" is only its '
            'last share in time'
        )
    controller = dataset.controller
    along = predict_along(model, controller, dataset.recording_rows())
    excerpt = controller.take(slice(test_start, stop))
    offline = model.predict(excerpt.q, excerpt.v, excerpt.a)
    stamps = dataset.stamps_ns
    # The replay counts its offset from the bag's first stamp, which is the dataset's first
    # (regularise keeps it); half a period of margin on each side against rounding.
    return Excerpt(
        dataset=dataset,
        test_start=test_start,
        test_stop=test_stop,
        stop=stop,
        is_clipped=is_clipped,
        along=along,
        offline=offline,
        start_offset_s=(int(stamps[test_start] - stamps[0]) - period_ns // 2) / NS_PER_S,
        duration_s=(int(stamps[stop - 1] - stamps[test_start]) + period_ns) / NS_PER_S,
        excerpt_start_s=(stamps[test_start] - stamps[0]) / NS_PER_S,
        excerpt_s=(stop - test_start) * robot.ipo_period_s,
    )
