"""The report: the findings' rules on known numbers, the friction share, and the written files."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any, ClassVar, Self

import numpy as np
import pytest

from id_learning.dataset.inputs import Motion
from id_learning.dataset.preprocess import prepare_dataset
from id_learning.errors import ConfigError
from id_learning.evaluation import report as report_module
from id_learning.evaluation.report import (
    ERROR_SPECTRA_PNG,
    HIGH_FRICTION_SHARE,
    OVERLAYS_DIR,
    ReportInput,
    check_findings,
    friction_share,
    high_friction_axes,
    write_report,
)
from id_learning.evaluation.report_signals import label_floor, richest_window, stretches_of
from id_learning.evaluation.scoring import label_noise_floor, score_model
from id_learning.evaluation.study import load_study_table
from id_learning.models.base import InverseDynamicsModel, ModelConfig, TorqueComponents
from id_learning.models.data import TrainingData, nominal_rnea

JOINTS = ('j1', 'j2', 'j3')
# Friction carries 80 % of j1's label, 20 % of j2's, 60 % of j3's: j1 and j3 are high-friction.
SHARE = np.array([0.8, 0.2, 0.6])


def errors(**by_kind: list[float]) -> dict[str, np.ndarray]:
    return {kind: np.array(values) for kind, values in by_kind.items()}


def by_key(findings):
    return {f.key: f for f in findings}


def test_high_friction_axes_are_those_above_the_threshold_or_else_the_largest():
    assert HIGH_FRICTION_SHARE == 0.5
    assert high_friction_axes(SHARE) == [0, 2]
    assert high_friction_axes(np.array([0.1, 0.3, 0.2])) == [1]


def test_motor_findings_hold_when_rnea_mlp_wins_on_friction_axes_and_lnn_mlp_closes_the_gap():
    rmse = errors(
        rnea_mlp=[0.10, 0.30, 0.10],
        delan=[0.40, 0.10, 0.30],  # better than RNEA+MLP on j2, which is not a friction axis
        lnn=[0.30, 0.10, 0.30],
        lnn_mlp=[0.12, 0.10, 0.14],  # closes (0.3 - 0.13) / (0.3 - 0.1) = 85 % of the gap
    )
    found = by_key(check_findings('motor', JOINTS, rmse, SHARE, {'delan': 'time_budget'}))
    assert found['rnea_mlp_beats_lagrangian'].holds is True
    assert 'j1, j3' in found['rnea_mlp_beats_lagrangian'].evidence
    # A verdict that rests on an under-trained model says so.
    assert 'DeLaN stopped at its time budget' in found['rnea_mlp_beats_lagrangian'].caveat
    assert found['lnn_mlp_recovers_gap'].holds is True
    assert 'gap recovered 85%' in found['lnn_mlp_recovers_gap'].evidence
    assert not found['lnn_mlp_recovers_gap'].why
    assert not found['lnn_mlp_recovers_gap'].caveat


def test_motor_finding_fails_and_names_the_axis_where_a_lagrangian_network_wins():
    rmse = errors(
        rnea_mlp=[0.10, 0.30, 0.20],
        delan=[0.40, 0.10, 0.30],
        lnn=[0.30, 0.10, 0.15],  # LNN beats RNEA+MLP on j3, a friction axis
        lnn_mlp=[0.28, 0.10, 0.16],
        mlp=[0.05, 0.3, 0.1],
    )
    stopped = {'rnea_mlp': 'time_budget', 'lnn_mlp': 'early_stopping'}
    found = by_key(check_findings('motor', JOINTS, rmse, SHARE, stopped))
    first = found['rnea_mlp_beats_lagrangian']
    assert first.holds is False
    assert 'on j3 a Lagrangian network is at or below RNEA+MLP' in first.why
    assert 'RNEA+MLP stopped at its time budget' in first.why
    assert 'worse than the plain MLP on j3' in first.why
    second = found['lnn_mlp_recovers_gap']
    # mean over j1, j3: LNN 0.225, LNN+MLP 0.22, RNEA+MLP 0.15: 0.005 / 0.075 recovered
    assert second.holds is False
    assert 'closes only 7%' in second.why


def test_gap_finding_fails_when_lnn_is_not_worse_than_rnea_mlp():
    rmse = errors(rnea_mlp=[0.3, 0.3, 0.3], delan=[0.2] * 3, lnn=[0.2] * 3, lnn_mlp=[0.2] * 3)
    found = by_key(check_findings('motor', JOINTS, rmse, SHARE))
    assert found['lnn_mlp_recovers_gap'].holds is False
    assert 'no gap to recover' in found['lnn_mlp_recovers_gap'].why


def test_findings_are_not_checked_when_a_model_is_missing():
    found = by_key(check_findings('motor', JOINTS, errors(rnea_mlp=[0.1] * 3), SHARE))
    assert found['rnea_mlp_beats_lagrangian'].holds is None
    assert 'lacks DeLaN, LNN' in found['rnea_mlp_beats_lagrangian'].why
    assert found['lnn_mlp_recovers_gap'].holds is None


def test_joint_label_finding_holds_within_the_competitive_ratio_and_explains_a_miss():
    competitive = errors(rnea_mlp=[0.1, 0.1, 0.1], delan=[0.12] * 3, lnn=[0.3] * 3)
    (finding,) = check_findings('joint', JOINTS, competitive, SHARE)
    assert finding.key == 'lagrangian_competitive'
    assert finding.holds is True
    assert 'DeLaN / RNEA+MLP = 1.20' in finding.evidence

    losing = errors(rnea_mlp=[0.1, 0.1, 0.1], delan=[0.2, 0.2, 0.5], lnn=[0.3] * 3)
    (finding,) = check_findings('joint', JOINTS, losing, SHARE, {'delan': 'time_budget'})
    assert finding.holds is False
    assert 'largest relative gap is on j3' in finding.why
    assert 'DeLaN stopped at its time budget' in finding.why
    assert 'still holds dissipation on j3 (friction share 60%)' in finding.why

    # A dissipation-free label, and a plain MLP that loses as much: the gap is the URDF prior.
    losing['mlp'] = np.array([0.3, 0.3, 0.3])
    (finding,) = check_findings('joint', JOINTS, losing, np.array([0.01, 0.02, 0.03]))
    assert finding.holds is False
    assert 'friction share below 10% on every axis' in finding.why
    assert 'the plain MLP is 3.00 x RNEA+MLP too' in finding.why


def test_friction_share_recovers_the_viscous_and_coulomb_part_of_a_known_label():
    t = np.arange(0.0, 100.0, 0.008)
    q = np.column_stack([np.sin(0.5 * t), 0.8 * np.sin(0.3 * t)])
    v = np.column_stack([0.5 * np.cos(0.5 * t), 0.24 * np.cos(0.3 * t)])
    friction = np.array([40.0, 2.0]) * v + np.array([15.0, 1.0]) * np.tanh(v / 0.01)
    gravity = np.array([50.0, 200.0]) * np.cos(q)
    tau = gravity + friction + 3.0
    # The nominal model knows 80 % of gravity: the rest and the offset stay in the remainder.
    remainder = tau - 0.8 * gravity
    expected = np.sqrt(np.mean(friction**2, axis=0) / np.mean(tau**2, axis=0))
    share = friction_share(tau, remainder, v)
    assert expected[0] > 0.2 > expected[1]  # one friction-dominated axis, one gravity axis
    np.testing.assert_allclose(share, expected, rtol=0.02, atol=1e-3)


class NominalPlusViscous(InverseDynamicsModel):
    """A stand-in model: the nominal RNEA plus a viscous friction term it reports as friction."""

    kind: ClassVar[str] = 'rnea_lq'

    def __init__(self, robot, gain: float) -> None:
        super().__init__(ModelConfig(kind='rnea_lq'), robot)
        self.gain = gain

    def fit(self, data: TrainingData, *, progress: bool = False) -> Self:
        return self

    def predict(self, q, v, a):
        return nominal_rnea(self.robot, q, v, a) + self.gain * v

    def components(self, q, v, a):
        rigid = nominal_rnea(self.robot, q, v, a)
        return TorqueComponents(
            total=rigid + self.gain * v, residual=rigid, friction=self.gain * v
        )

    def state(self) -> dict[str, np.ndarray]:
        return {}

    def load_state(self, tensors: dict[str, np.ndarray], fitted: dict[str, Any]) -> None:
        return None


@pytest.fixture(scope='module')
def report_input(mabi, short_twin):
    _, result = short_twin
    dataset = replace(prepare_dataset(result.recording, mabi), tau_clean=result.tau_u_clean)
    rows = [(dataset.n_train, len(dataset.q))]
    scale = dataset.target_scaler.scale()
    models = {
        'rnea_lq': NominalPlusViscous(mabi, 300.0),
        'rnea_mlp': NominalPlusViscous(mabi, 100.0),
    }
    metrics = {}
    for kind, model in models.items():
        metrics[kind] = {
            **score_model(model, dataset, scale).metrics,
            'train_seconds': 1.5,
            'history': {'epochs': 4, 'stopped_by': 'early_stopping'},
            'inference_seconds_per_sample': 2e-6,
            'latency_single_sample_median_s': 1e-4,
            'latency_single_sample_p99_s': 2e-4,
        }
    return ReportInput(
        title='A test report',
        robot=mabi,
        dataset=dataset,
        rows=rows,
        evaluated_on='the test part',
        target_scale=scale,
        models=models,
        metrics=metrics,
        noise_floor=label_noise_floor(dataset),
    )


def test_the_report_has_both_rmse_tables_timings_findings_and_its_png_figures(
    report_input, tmp_path
):
    path, findings = write_report(report_input, tmp_path)
    text = path.read_text()
    assert text.startswith('# A test report')
    assert '| RNEA+LQ |' in text
    assert '| RNEA+MLP |' in text
    assert 'Per-joint test RMSE through the label filter [N·m]' in text
    assert '| label-noise floor |' in text
    assert 'as a multiple of the label-noise floor' in text
    assert 'Against the noise-free torque (twin ground truth)' in text
    assert "The study's way [N·m] (for comparison)" in text
    assert 'normalised [-1, 1] scale' in text
    assert "**The study's Table 1 is not given**" in text
    assert 'arXiv:2506.17994' in text
    # Two models cannot decide the motor-label findings: they are listed as not checked.
    assert [f['holds'] for f in findings] == [None, None]
    assert 'not checked' in text
    figures = (
        'rmse_per_joint.png',
        'abs_error_boxplot.png',
        'dissipative_axis1.png',
        'torque_shares.png',
        f'{OVERLAYS_DIR}/rnea_lq.png',
        f'{OVERLAYS_DIR}/rnea_mlp.png',
        ERROR_SPECTRA_PNG,
    )
    section = text.split('## Figures')[1]
    for name in figures:
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b'\x89PNG\r\n\x1a\n'
        assert len(data) > 20_000
        # Linked under its heading, after a sentence saying what it shows.
        heading, sentence, link = _figure_block(section, name)
        assert heading.startswith('### (')
        assert sentence.endswith('.')
        assert len(sentence) > 60
        assert link.startswith('![')
    assert 'RNEA+MLP: predicted against measured torque' in section
    assert 'the dashed line is the label-noise floor as white noise through the label filter' in (
        section
    )


def _figure_block(section: str, name: str) -> tuple[str, str, str]:
    """The heading, sentence and link of the figure ``name`` in the figures section."""
    lines = [line for line in section.splitlines() if line]
    (k,) = [i for i, line in enumerate(lines) if line.endswith(f']({name})')]
    return lines[k - 2], lines[k - 1], lines[k]


def test_without_the_noise_free_torque_the_floor_is_estimated_from_the_raw_labels(report_input):
    rows = report_input.dataset.test_rows
    measured = label_floor(report_input.dataset, rows, report_input.noise_floor)
    assert measured.label == 'label-noise floor'
    np.testing.assert_array_equal(measured.rms_nm, report_input.noise_floor)
    estimated = label_floor(replace(report_input.dataset, tau_clean=None), rows, None)
    assert 'estimate' in estimated.label
    # The twin's noise is white in the raw label: the estimate finds the floor's order.
    ratio = estimated.rms_nm / report_input.noise_floor
    assert np.all((ratio > 0.3) & (ratio < 3.0)), ratio


def test_the_overlay_window_is_where_all_joints_move_most():
    n, period = 3000, 0.008
    t = np.arange(n) * period
    v = np.tile(0.01 * np.sin(t)[:, None], (1, 2))
    burst = slice(2200, 2500)  # in the second evaluated range, a fast stretch on both joints
    v[burst] += np.sin(2 * np.pi * 2.0 * t[burst])[:, None]
    motion = Motion(np.zeros_like(v), v, np.gradient(v, period, axis=0))
    rows = [(0, 1000), (1500, 3000)]
    start, stop = richest_window(motion, rows, 300)
    assert stop - start == 300
    assert abs(start - 2200) <= 10
    # No range holds the window: the longest range whole.
    assert richest_window(motion, rows, 2000) == (1500, 3000)
    assert stretches_of(rows) == [(0, 1000), (1000, 2500)]


AXES = [f'axis_{k}' for k in range(1, 7)]


def write_table(path, rows, joints=None, **extra):
    joints = joints or [f'axis_{k}' for k in range(1, 7)]
    path.write_text(json.dumps({'joints': joints, 'rmse_normalised': rows, **extra}))
    return path


def test_the_report_places_the_study_table_beside_ours(report_input, tmp_path):
    # Placeholder values, not the study's: they only exercise the table's layout.
    path = write_table(
        tmp_path / 'table1.json',
        {'rnea_lq': [0.5] * 6, 'lstm': [0.25] * 6},
        metric='test RMSE (placeholder)',
        findings=['placeholder finding'],
    )
    table = load_study_table(path, n_joints=6)
    drawn, draw = {}, report_module.plot_rmse

    def plot_rmse(joints, errors, path, floor=None, floor_label=''):
        drawn.update(floor=floor, label=floor_label)
        return draw(joints, errors, path, floor, floor_label)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(report_module, 'plot_rmse', plot_rmse)
        out, _ = write_report(replace(report_input, study_table=table), tmp_path / 'report')
    # The RMSE figure draws the table's label-noise floor, on its normalised scale.
    expected = report_input.noise_floor / report_input.target_scale
    np.testing.assert_allclose(drawn['floor'], expected)
    assert drawn['label'] == 'label-noise floor'
    text = out.read_text()
    assert 'not given' not in text
    assert 'joint_1 ours / study' in text
    ours = report_input.metrics['rnea_lq']['study_way']['rmse_normalised']
    assert f'| RNEA+LQ | {ours[0]:.3g} / 0.5 |' in text
    assert '/ – |' in text  # a model the table lacks
    assert '| LSTM (not trained here) | – / 0.25 |' in text
    assert 'Its metric: test RMSE (placeholder).' in text
    assert '- placeholder finding' in text
    assert str(path) in text


def test_the_studys_findings_are_also_decided_on_the_studys_own_numbers(report_input, tmp_path):
    # Placeholder values built so that the rules give known verdicts: RNEA+MLP below DeLaN and
    # LNN on every axis, and LNN+MLP closing a third of LNN's gap (below the rule's share).
    rows = {
        'rnea_mlp': [0.1] * 6,
        'delan': [0.4] * 6,
        'lnn': [0.4] * 6,
        'lnn_mlp': [0.3] * 6,
    }
    table = load_study_table(write_table(tmp_path / 'table1.json', rows), n_joints=6)
    out, _ = write_report(replace(report_input, study_table=table), tmp_path / 'report')
    text = out.read_text()
    after = text.split("The same rules on the study's own Table 1")[1]
    assert '**rnea_mlp_beats_lagrangian: holds.**' in after
    assert '**lnn_mlp_recovers_gap: does NOT hold.**' in after
    assert 'gap recovered 33%' in after
    # Without a table the section has no such part.
    plain, _ = write_report(report_input, tmp_path / 'plain')
    assert "study's own Table 1" not in plain.read_text()


@pytest.mark.parametrize(
    ('content', 'message'),
    [
        ({'joints': AXES}, "lacks 'rmse_normalised'"),
        ({'joints': AXES, 'rmse_normalised': {'mlp': [0.1] * 5}}, 'needs 6 finite values'),
        (
            {'joints': AXES, 'rmse_normalised': {'mlp': [0.1] * 5 + ['x']}},
            'rmse_normalised.mlp',
        ),
        ({'joints': AXES, 'rmse_normalised': {'mlp': [0.1] * 5 + [float('nan')]}}, 'finite'),
        ({'joints': [*AXES, 'axis_7'], 'rmse_normalised': {}}, '7 axes, the robot 6 joints'),
        ([1, 2], 'must be a JSON object'),
    ],
)
def test_a_bad_study_table_is_refused_naming_file_and_key(tmp_path, content, message):
    path = tmp_path / 'bad.json'
    path.write_text(json.dumps(content))
    with pytest.raises(ConfigError, match=message) as err:
        load_study_table(path, n_joints=6)
    assert str(path) in str(err.value)


def test_a_missing_study_table_file_is_refused(tmp_path):
    with pytest.raises(ConfigError, match='cannot read study table'):
        load_study_table(tmp_path / 'absent.json')


def test_a_study_table_naming_a_model_twice_is_refused(tmp_path):
    path = tmp_path / 'twice.json'
    row = '[0.1, 0.1, 0.1, 0.1, 0.1, 0.1]'
    path.write_text(
        f'{{"joints": ["a", "b", "c", "d", "e", "f"], '
        f'"rmse_normalised": {{"mlp": {row}, "mlp": {row.replace("0.1", "0.9")}}}}}'
    )
    with pytest.raises(ConfigError, match="key 'mlp' appears twice") as err:
        load_study_table(path, n_joints=6)
    assert str(path) in str(err.value)
