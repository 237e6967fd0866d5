"""From bags and logs to training data: recordings, import, inspection, preprocessing."""

from __future__ import annotations

from id_learning.dataset.import_mapping import ImportMapping, load_import_mapping
from id_learning.dataset.importer import ImportReport, import_log
from id_learning.dataset.inputs import InputDefinition, Motion
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.inspect_plot import plot_report
from id_learning.dataset.inspect_report import BagReport
from id_learning.dataset.inspect_text import render_report
from id_learning.dataset.preprocess import (
    PREPROCESS_MODES,
    Dataset,
    MinMaxScaler,
    PreprocessConfig,
    Split,
    differentiate,
    lowpass,
    prepare_dataset,
    regularise,
)
from id_learning.dataset.recording import Recording, load_recording, write_recording

__all__ = [
    'PREPROCESS_MODES',
    'BagReport',
    'Dataset',
    'ImportMapping',
    'ImportReport',
    'InputDefinition',
    'MinMaxScaler',
    'Motion',
    'PreprocessConfig',
    'Recording',
    'Split',
    'differentiate',
    'import_log',
    'inspect_bag',
    'load_import_mapping',
    'load_recording',
    'lowpass',
    'plot_report',
    'prepare_dataset',
    'regularise',
    'render_report',
    'write_recording',
]
