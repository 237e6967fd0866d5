"""From bags and logs to training data: recordings, import, inspection, preprocessing."""

from __future__ import annotations

from id_learning.dataset.importer import (
    ImportMapping,
    ImportReport,
    import_log,
    load_import_mapping,
)
from id_learning.dataset.inputs import InputDefinition, Motion
from id_learning.dataset.inspect import BagReport, inspect_bag, plot_report, render_report
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
