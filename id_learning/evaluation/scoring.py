"""How good a model's torque is: through the label filter, the study's way, and against the truth.

The labels are low-passed torques (``Dataset.cutoff_hz``). A model predicts the torque the drive
needs now, from the inputs a controller sends; it is judged where the labels can judge it:

- through the filter (the primary figure): the model's torque along each whole recording, on a
  controller's inputs (``Dataset.controller``), low-passed exactly like the labels, against the
  labels on the test part;
- the study's way (a labelled extra): the model on the study's inputs (q and v low-passed like
  the labels), its torque against the labels as is; what the reference study reports;
- against the truth (twin recordings, ``Dataset.tau_clean``): the filtered torque against the
  noise-free torque filtered the same way, and the unfiltered torque against the noise-free one;
- the label-noise floor: the filtered labels against the filtered noise-free torque, the best
  any model can do through the filter;
- the torque the drive needs (twin recordings, ``twin.needed_torque``): the model on the planned
  reference a controller sends, against the noise-free torque of that motion at each sample
  time, without the label's delay: the feed-forward error a drive would see.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from id_learning.dataset.inputs import Motion
from id_learning.dataset.preprocess import Dataset
from id_learning.evaluation.metrics import error_metrics, rmse
from id_learning.models.base import InverseDynamicsModel
from id_learning.twin.needed_torque import needed_torque_of

__all__ = ['ModelScore', 'label_noise_floor', 'predict_along', 'score_model', 'test_index']


def test_index(dataset: Dataset) -> np.ndarray:
    """Rows of the test part of every recording, in dataset row order."""
    return dataset.test_rows


def predict_along(
    model: InverseDynamicsModel, motion: Motion, runs: Sequence[np.ndarray]
) -> np.ndarray:
    """A model's torque (N, n) [N*m] on given rows; each run (rows in time order) on its own.

    Sequence models need runs contiguous in time; for the others the runs only group rows.
    Rows outside every run are NaN.
    """
    out = np.full(motion.q.shape, np.nan)
    for rows in runs:
        if len(rows):
            out[rows] = model.predict(motion.q[rows], motion.v[rows], motion.a[rows])
    return out


def label_noise_floor(dataset: Dataset) -> np.ndarray | None:
    """(n,) RMS of filtered label minus filtered noise-free torque on the test part [N*m].

    None without the noise-free torque (recordings of a real robot).
    """
    if dataset.tau_clean is None:
        return None
    rows = test_index(dataset)
    clean = dataset.filter_like_labels(dataset.tau_clean)
    return rmse(dataset.tau[rows], clean[rows])


class ModelScore:
    """Every figure of one model on one dataset's test part.

    Attributes:
        metrics: the JSON-ready metrics.json entry (see ``score_model``).
        filtered: (M, n) the torque through the filter on the test rows [N*m].
        unfiltered: (M, n) the torque on a controller's inputs on the test rows [N*m].
        study_way: (M, n) the torque on the study's inputs on the test rows [N*m].
        predicted_samples: how many samples the model was run on for these figures.
    """

    def __init__(
        self,
        metrics: dict[str, object],
        filtered: np.ndarray,
        unfiltered: np.ndarray,
        study_way: np.ndarray,
        predicted_samples: int,
    ) -> None:
        """Keep the figures and the predictions they came from."""
        self.metrics = metrics
        self.filtered = filtered
        self.unfiltered = unfiltered
        self.study_way = study_way
        self.predicted_samples = predicted_samples


def score_model(model: InverseDynamicsModel, dataset: Dataset, scale: np.ndarray) -> ModelScore:
    """Score a model on the test part of a dataset (see the module docstring).

    Args:
        model: a fitted model.
        dataset: the recordings, whole (their test part is scored).
        scale: (n,) half ranges of the training labels [N*m] (the study's normalisation).

    Returns:
        The score. ``metrics`` holds the through-filter figures under the error-metric names
        (``rmse_nm``, ``rmse_normalised``, ...) and again as ``rmse_through_filter_nm``,
        ``rmse_through_filter_normalised`` and ``mean_rmse_through_filter_normalised``; the
        study's way in ``study_way``; with a noise-free torque ``rmse_true_through_filter_nm``,
        ``rmse_true_nm`` and ``rmse_through_filter_over_floor``; with the torque the drive
        needs as well (a twin bag, ``twin.needed_torque_of``) ``rmse_needed_nm`` (the model on
        the planned reference against it, unfiltered) and ``rmse_needed_over_floor``.
    """
    rows = test_index(dataset)
    torque = predict_along(model, dataset.controller, dataset.recording_rows())
    filtered = dataset.filter_like_labels(torque)[rows]
    through = error_metrics(filtered, dataset.tau[rows], scale).to_dict()
    if dataset.is_shuffled:  # scattered test rows: along each recording, then picked
        test_runs = dataset.recording_rows()
    else:
        test_runs = [np.arange(*s['test']) for s in dataset.extra.get('segments', [])] or [rows]
    study = predict_along(model, dataset.study, test_runs)[rows]
    predicted = len(dataset.tau) + sum(len(run) for run in test_runs)
    study_way = error_metrics(study, dataset.tau[rows], scale).to_dict()
    metrics: dict[str, object] = {
        **through,
        'metric': 'through_filter',
        'rmse_through_filter_nm': through['rmse_nm'],
        'rmse_through_filter_normalised': through['rmse_normalised'],
        'mean_rmse_through_filter_normalised': through['mean_rmse_normalised'],
        'study_way': {
            'inputs': 'q and v low-passed like the labels; the torque compared as is',
            **{
                key: study_way[key]
                for key in ('rmse_nm', 'rmse_normalised', 'mean_rmse_normalised', 'nmse')
            },
        },
    }
    if dataset.tau_clean is not None:
        clean = dataset.tau_clean[rows]
        clean_filtered = dataset.filter_like_labels(dataset.tau_clean)[rows]
        floor = rmse(dataset.tau[rows], clean_filtered)
        metrics['rmse_true_through_filter_nm'] = rmse(filtered, clean_filtered).tolist()
        metrics['rmse_true_nm'] = rmse(torque[rows], clean).tolist()
        floor = np.where(floor > 0, floor, np.nan)
        metrics['rmse_through_filter_over_floor'] = (
            np.asarray(through['rmse_nm']) / floor
        ).tolist()
        needed = needed_torque_of(dataset)
        if needed is not None:
            on_reference = predict_along(model.for_the_drive(), needed.reference, test_runs)[rows]
            predicted += sum(len(run) for run in test_runs)
            needed_rmse = rmse(on_reference, needed.torque[rows])
            metrics['rmse_needed_nm'] = needed_rmse.tolist()
            metrics['rmse_needed_over_floor'] = (needed_rmse / floor).tolist()
    return ModelScore(metrics, filtered, torque[rows], study, predicted)
