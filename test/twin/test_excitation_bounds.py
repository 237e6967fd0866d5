"""Twin settings a recording cannot honour: aliased excitation, absurd delays, rounded lengths."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from support import REPO

from id_learning.errors import ConfigError
from id_learning.record.excitation import ExcitationConfig, check_bandwidth, design_excitation
from id_learning.robot import RobotConfig
from id_learning.twin import load_twin_config

IPO_S = 0.008  # Nyquist 62.5 Hz


def _twin_file(tmp_path: Path, section: str, values: dict[str, object]) -> Path:
    data = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text(encoding='utf-8'))
    data['robot'] = str(REPO / 'config/mabi_max100.yaml')
    data.setdefault(section, {}).update(values)
    path = tmp_path / 'twin.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


@pytest.mark.parametrize(('base', 'harmonics'), [(50.0, 3), (62.5, 1), (20.84, 3)])
def test_harmonics_at_or_above_nyquist_are_refused(base: float, harmonics: int) -> None:
    with pytest.raises(ConfigError, match=r'Nyquist frequency 62\.5 Hz.*use base_frequency_hz <'):
        check_bandwidth(base, harmonics, IPO_S, 'excitation')


def test_harmonics_below_nyquist_pass() -> None:
    check_bandwidth(20.8, 3, IPO_S, 'excitation')
    check_bandwidth(0.04, 3, IPO_S, 'excitation')


def test_a_twin_config_with_an_aliased_excitation_is_refused_at_load(tmp_path: Path) -> None:
    path = _twin_file(tmp_path, 'excitation', {'base_frequency_hz': 50})
    with pytest.raises(ConfigError, match=r'excitation: base_frequency_hz 50 Hz x 3'):
        load_twin_config(path)


def test_design_refuses_an_aliased_excitation_too(mabi: RobotConfig) -> None:
    config = ExcitationConfig(duration_s=1.0, base_frequency_hz=30.0, harmonics=3, rest_s=0.0)
    with pytest.raises(ConfigError, match='Nyquist'):
        design_excitation(config, mabi.limits, mabi.ipo_period_s, np.random.default_rng(0))


@pytest.mark.parametrize('delay', [10.0, 0.1001])
def test_a_signal_delay_beyond_the_bound_is_refused_with_the_reason(
    tmp_path: Path, delay: float
) -> None:
    path = _twin_file(tmp_path, 'effects', {'signal_delay': {'enabled': True, 'delay_s': delay}})
    with pytest.raises(
        ConfigError, match=r'signal_delay\.delay_s: must be <= 0\.1 s.*first order'
    ):
        load_twin_config(path)


def test_a_signal_delay_within_the_bound_is_kept(tmp_path: Path) -> None:
    path = _twin_file(tmp_path, 'effects', {'signal_delay': {'enabled': True, 'delay_s': 0.1}})
    assert load_twin_config(path).effects.get('signal_delay').delay_s == 0.1


@pytest.mark.parametrize(
    ('duration', 'actual', 'noted'),
    [(5.0, 26.0, True), (26.0, 26.0, False), (600.0, 587.0, True), (51.5, 51.5, False)],
)
def test_the_length_is_rounded_to_whole_segments_and_said(
    duration: float, actual: float, noted: bool
) -> None:
    config = ExcitationConfig(duration_s=duration)
    assert config.actual_duration_s == pytest.approx(actual)
    note = config.duration_note(IPO_S)
    assert (note is not None) == noted
    if note:
        assert f'{duration:g} s became {actual:g} s' in note
        assert 'whole segment' in note


def test_simulate_warns_when_it_rounds_the_length(caplog: pytest.LogCaptureFixture) -> None:
    from support import twin_config

    from id_learning.twin import simulate

    config = twin_config(5.0)
    with caplog.at_level(logging.WARNING, logger='id_learning.twin.simulate'):
        result = simulate(replace(config))
    assert result.recording.duration_s == pytest.approx(26.0)
    assert any('duration_s 5 s became 26 s' in r.getMessage() for r in caplog.records)
