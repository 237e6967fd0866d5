"""``id-learning diagnose`` end to end, and its rnea_effects model through train and evaluate."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support import REPO, run_cli, twin_config

from id_learning.models.registry import load_model
from id_learning.physics import AugmentedModel
from id_learning.twin import simulate, write_twin_output

ROBOT = str(REPO / 'config/mabi_max100.yaml')
COULOMB_J4 = 12.0  # N*m, hidden on joint 4 of an otherwise nominal twin


@pytest.fixture(scope='module')
def hidden_bag(tmp_path_factory):
    effects = {'coulomb_friction': {'enabled': True, 'level': [0, 0, 0, COULOMB_J4, 0, 0]}}
    config = twin_config(150.0, effects, seed=8)
    return write_twin_output(simulate(config), config, tmp_path_factory.mktemp('bag') / 'twin')


@pytest.fixture(scope='module')
def diagnosed(hidden_bag, tmp_path_factory):
    out = tmp_path_factory.mktemp('diagnose') / 'out'
    result = run_cli('diagnose', '--bag', str(hidden_bag), '--robot', ROBOT, '--out', str(out))
    assert result.returncode == 0, result.stderr
    return out, result.stdout


def test_diagnose_names_the_hidden_effect_and_prints_the_waterfall(diagnosed):
    out, stdout = diagnosed
    assert 'coulomb_friction on joint_4' in stdout
    assert 'waterfall:' in stdout
    effects = json.loads((out / 'effects.json').read_text())
    found = [(e['name'], e['joint']) for e in effects['effects'] if e['status'] == 'found']
    assert found == [('coulomb_friction', 'joint_4')]
    (level,) = effects['effects'][0]['parameters']
    assert level['value'] == pytest.approx(COULOMB_J4, rel=0.1)
    before, after = effects['held_out_rmse_nm']['before'], effects['held_out_rmse_nm']['after']
    assert after[3] < 0.5 * before[3]
    assert (out / 'waterfall.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert '![waterfall.png](waterfall.png)' in (out / 'report.md').read_text()


def test_the_saved_model_is_the_diagnosis_refit_model(diagnosed, mabi):
    out, _ = diagnosed
    model = load_model(out / 'model', mabi, 'rnea_effects')
    saved = json.loads((out / 'effects.json').read_text())['model']
    rng = np.random.default_rng(0)
    q, v, a = (rng.uniform(-1, 1, (9, 6)) for _ in range(3))
    np.testing.assert_array_equal(
        model.predict(q, v, a), AugmentedModel.from_dict(saved, mabi).torque(q, v, a)
    )


def test_train_and_evaluate_accept_the_diagnosed_model_and_an_mlp_on_top(
    diagnosed, hidden_bag, tmp_path
):
    out, _ = diagnosed
    run = tmp_path / 'run'
    result = run_cli(
        'train',
        '--bag',
        str(hidden_bag),
        '--robot',
        ROBOT,
        '--models',
        'rnea_lq,rnea_effects,rnea_effects_mlp',
        '--hyper',
        f'rnea_effects.effects={out}',
        '--hyper',
        f'rnea_effects_mlp.effects={out / "effects.json"}',
        '--hyper',
        'rnea_effects_mlp.max_epochs=1',
        '--device',
        'cpu',
        '--out',
        str(run),
        '--quiet',
    )
    assert result.returncode == 0, result.stderr
    assert 'RNEA+effects+MLP' in result.stdout
    metrics = json.loads((run / 'metrics.json').read_text())
    rmse = {kind: np.asarray(entry['rmse_nm']) for kind, entry in metrics['models'].items()}
    # joint 4's hidden Coulomb friction is in the diagnosed model, not in the viscous-only LQ
    assert rmse['rnea_effects'][3] < 0.5 * rmse['rnea_lq'][3]
    evaluation = run_cli(
        'evaluate', '--run', str(run), '--bag', str(hidden_bag), '--out', str(tmp_path / 'ev')
    )
    assert evaluation.returncode == 0, evaluation.stderr
    evaluated = json.loads((tmp_path / 'ev/metrics.json').read_text())
    np.testing.assert_allclose(
        evaluated['models']['rnea_effects']['rmse_nm'], rmse['rnea_effects'], rtol=1e-9
    )


def test_diagnose_refuses_bad_input_with_one_clear_line(tmp_path, hidden_bag):
    missing = run_cli('diagnose', '--bag', str(tmp_path / 'nope'), '--out', str(tmp_path / 'x'))
    assert missing.returncode == 2
    assert 'no such bag' in missing.stderr
    assert 'Traceback' not in missing.stderr
    unknown = run_cli(
        'diagnose', '--bag', str(hidden_bag), '--effects', 'warp_drive', '--out', str(tmp_path)
    )
    assert unknown.returncode == 2
    assert "unknown effect(s) ['warp_drive']" in unknown.stderr
