"""The diagnosis keeps a time budget and says what it left out."""

from __future__ import annotations

import json

import pytest
from support import twin_config

from id_learning.diagnosis import DiagnosisConfig
from id_learning.diagnosis.pipeline import run_diagnosis
from id_learning.errors import ConfigError
from id_learning.twin import simulate


def test_a_diagnosis_past_its_budget_selects_nothing_more_and_says_so(mabi):
    twin = simulate(twin_config(120.0, seed=3))
    result = run_diagnosis(twin.recording, mabi, DiagnosisConfig(max_seconds=1e-6))
    assert result.cut_short[0] == 'selection steps'
    assert result.stop_reason == 'the time budget ran out'
    assert result.effects == []
    assert json.loads(result.to_json())['cut_short'] == result.cut_short
    unlimited = run_diagnosis(twin.recording, mabi)
    assert unlimited.cut_short == []
    assert unlimited.effects


def test_a_budget_must_be_positive():
    with pytest.raises(ConfigError, match='max_seconds'):
        DiagnosisConfig(max_seconds=0.0)


def test_a_diagnosis_cut_after_its_first_selection_still_assembles(mabi, monkeypatch):
    """Every optional step after the first selection refused (as a budget that ran out there
    does): the whole model's forms, which relabel candidates, must not be half applied."""
    from id_learning.diagnosis import pipeline

    def refuse(budget, step):
        budget.skipped.append(step)
        return False

    monkeypatch.setattr(pipeline._Budget, 'allows', refuse)
    twin = simulate(twin_config(120.0, seed=3))
    result = run_diagnosis(twin.recording, mabi)
    assert result.effects
    assert 'the selection with the whole model' in result.cut_short
    assert all('whole model' not in effect.spec.label for effect in result.effects)
