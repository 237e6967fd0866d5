"""Loading twin bags: a ground truth that is ignored, or carried by some bags only, is said."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import pytest
from support import twin_config

from id_learning.dataset.preprocess import PreprocessConfig
from id_learning.evaluation.report_tables import _through_filter_tables
from id_learning.training.datasets import (
    DATA_WARNINGS,
    GROUND_TRUTH_NOTES,
    combine_datasets,
    load_datasets,
)
from id_learning.twin import GROUND_TRUTH_ARRAYS, GROUND_TRUTH_JSON, simulate, write_twin_output


@pytest.fixture(scope='module')
def twin_bags(tmp_path_factory):
    """Two 26 s twin bags with different seeds and the same start time (so the same stamps)."""
    folder = tmp_path_factory.mktemp('gt')
    paths = []
    for seed in (31, 32):
        config = twin_config(30.0, seed=seed)
        paths.append(write_twin_output(simulate(config), config, folder / f'twin_{seed}'))
    return paths


def _copy(bag: Path, out: Path, *, truth_from: Path | None) -> Path:
    """A copy of ``bag`` whose ground-truth files come from ``truth_from`` (None: removed)."""
    shutil.copytree(bag, out)
    for name in (GROUND_TRUTH_ARRAYS, GROUND_TRUTH_JSON):
        (out / name).unlink()
        if truth_from is not None:
            shutil.copy(truth_from / name, out / name)
    return out


def _no_floor_sentence(dataset) -> str:
    """The report's section (a) without a floor, for one model."""
    metrics = {'rnea_lq': {'rmse_nm': [1.0] * 6}}
    return '\n'.join(_through_filter_tables(dataset, metrics, ['rnea_lq'], None))


def test_both_bags_with_their_own_truth_keep_it(twin_bags, mabi):
    datasets = load_datasets(twin_bags, mabi, PreprocessConfig(), progress=False)
    combined = combine_datasets(datasets)
    assert combined.tau_clean is not None
    assert combined.extra[GROUND_TRUTH_NOTES] == []


def test_a_bag_without_truth_beside_one_with_it_is_said(twin_bags, mabi, tmp_path, caplog):
    bare = _copy(twin_bags[1], tmp_path / 'bare', truth_from=None)
    with caplog.at_level(logging.WARNING):
        datasets = load_datasets([twin_bags[0], bare], mabi, PreprocessConfig(), progress=False)
    combined = combine_datasets(datasets)
    assert combined.tau_clean is None
    (note,) = combined.extra[GROUND_TRUTH_NOTES]
    assert note.startswith(f'of the bags, only {twin_bags[0]} carries a twin ground truth')
    assert f'{bare} does not' in note
    assert note in combined.extra[DATA_WARNINGS]
    assert note in caplog.text
    assert f'No label-noise floor and no errors against the noise-free torque: {note}' in (
        _no_floor_sentence(combined)
    )


def test_the_truth_of_another_recording_is_ignored_by_name(twin_bags, mabi, tmp_path, caplog):
    mixed = _copy(twin_bags[0], tmp_path / 'mixed', truth_from=twin_bags[1])
    with caplog.at_level(logging.WARNING):
        (dataset,) = load_datasets([mixed], mabi, PreprocessConfig(), progress=False)
    assert dataset.tau_clean is None
    (note,) = dataset.extra[GROUND_TRUTH_NOTES]
    assert note.startswith(f'{mixed / GROUND_TRUTH_ARRAYS} does not belong to this recording')
    assert note in caplog.text
    assert note in dataset.extra[DATA_WARNINGS]
    assert note in _no_floor_sentence(combine_datasets([dataset]))


def test_a_bag_without_any_truth_gets_no_note(twin_bags, mabi, tmp_path):
    bare = _copy(twin_bags[1], tmp_path / 'bare', truth_from=None)
    (dataset,) = load_datasets([bare], mabi, PreprocessConfig(), progress=False)
    assert dataset.extra.get(GROUND_TRUTH_NOTES, []) == []
    assert 'No label-noise floor' not in _no_floor_sentence(combine_datasets([dataset]))
