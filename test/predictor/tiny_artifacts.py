"""Tiny fitted artifacts of every model kind, built in seconds (for predictor and node tests).

Each kind is fitted for one epoch on a 10 s synthetic sine recording with the smallest networks,
then saved with the registry: the weights are meaningless, but the artifacts are complete (scalers,
training ranges, hyper-parameters) and load like trained ones.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from support import quick_preprocess, sine_recording

#: Per kind, the smallest hyper-parameters that still exercise the model's code paths.
TINY_HYPER: dict[str, dict[str, object]] = {
    'rnea_lq': {},
    'rnea_id': {},
    'rnea_mlp': {'width': 8, 'depth': 1, 'max_epochs': 1, 'device': 'cpu', 'stride': 16},
    'delan': {'width': 8, 'depth': 1, 'max_epochs': 1, 'device': 'cpu', 'stride': 16},
    'lnn': {'width': 8, 'depth': 1, 'max_epochs': 1, 'device': 'cpu', 'stride': 16},
    'lnn_mlp': {
        'width': 8,
        'depth': 1,
        'max_epochs': 1,
        'device': 'cpu',
        'stride': 16,
        'dissipation_width': 8,
        'dissipation_depth': 1,
    },
    'mlp': {'width': 8, 'depth': 1, 'max_epochs': 1, 'device': 'cpu', 'stride': 16},
    'lstm': {'hidden_size': 8, 'num_layers': 1, 'max_epochs': 1, 'device': 'cpu', 'stride': 32},
}


def training_recording(n_samples: int = 1250):
    """The synthetic recording the tiny models are fitted on (10 s at 125 Hz)."""
    return sine_recording(n_samples)


def build_tiny_artifacts(folder: Path, robot, kinds=None) -> dict[str, Path]:
    """Fit and save one tiny model per kind into folder/<kind>; returns the folders."""
    import torch

    from id_learning.dataset import prepare_dataset
    from id_learning.models.data import TrainingData
    from id_learning.models.registry import STUDY_MODELS, make_model, save_model

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        preprocess = quick_preprocess(robot.n_joints)
        data = TrainingData(prepare_dataset(training_recording(), robot, preprocess), robot)
        out = {}
        for kind in kinds or STUDY_MODELS:
            model = make_model(kind, robot, **TINY_HYPER[kind]).fit(data)
            out[kind] = save_model(model, folder / kind)
    finally:
        torch.set_num_threads(threads)
    return out


def reference_run(n_samples: int = 60, start: int = 300, stamp_offset_ns: int = 0):
    """A smooth reference run (stamps [ns], q, v, a) inside the tiny models' training range."""
    recording = sine_recording(start + n_samples)
    q = recording.position[start:]
    v = recording.velocity[start:]
    a = np.gradient(v, 0.008, axis=0)
    stamps = recording.stamps_ns[start:] + stamp_offset_ns
    return stamps, q, v, a
