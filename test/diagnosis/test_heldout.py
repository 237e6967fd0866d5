"""Held-out judging over blocks of time and the per-joint fallback to the nominal model."""

from __future__ import annotations

import numpy as np
import pytest

from id_learning.diagnosis.design import Design
from id_learning.diagnosis.heldout import MIN_BLOCKS, fallback_joints, judge_effects
from id_learning.errors import RobotModelError
from id_learning.physics.augmented import AugmentedModel
from id_learning.physics.terms import EffectSpec

M = 600  # rows per part


def design_of(columns: dict[str, np.ndarray], y: np.ndarray) -> Design:
    """Train = first M rows, test = the next M; two joints, unit weights."""
    split = {'train': slice(0, M), 'test': slice(M, 2 * M)}
    return Design(
        {part: y[rows] for part, rows in split.items()},
        {label: {part: x[rows] for part, rows in split.items()} for label, x in columns.items()},
        np.ones(2),
        {part: np.full(2, float(M)) for part in split},
    )


def on_joint(x: np.ndarray, joint: int) -> np.ndarray:
    out = np.zeros((len(x), 2, 1))
    out[:, joint, 0] = x
    return out


@pytest.fixture
def problem() -> tuple[Design, np.ndarray]:
    """Joint 0 carries a real effect; 'spurious' fits joint 1's training noise and hurts its test.

    The spurious column copies the training part's noise on joint 1 and the negated noise on the
    test part: in-sample it explains a lot, held out it doubles the error.
    """
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 60.0, 2 * M)
    real = np.sin(t)
    noise = 0.1 * rng.standard_normal((2 * M, 2))
    y = noise.copy()
    y[:, 0] += 2.0 * real
    spurious = noise[:, 1].copy()
    spurious[M:] *= -1.0
    columns = {'real': on_joint(real, 0), 'spurious': on_joint(spurious, 1)}
    blocks = np.repeat(np.arange(10), M // 10)
    return design_of(columns, y), blocks


def test_an_effect_that_holds_out_is_significant_and_one_that_does_not_is_not(problem) -> None:
    design, blocks = problem
    selected = ['real', 'spurious']
    tests = judge_effects(design, selected, design.fit(selected), blocks, block_s=1.0)
    assert tests['real'].p_value < 1e-6
    assert tests['real'].gain == pytest.approx(1.0, abs=0.02)  # joint 0's whole disagreement
    assert tests['spurious'].p_value > 0.5
    assert tests['spurious'].gain < 0
    assert tests['real'].n_blocks == 10


def test_too_few_blocks_judge_nothing(problem) -> None:
    design, _ = problem
    blocks = np.repeat(np.arange(MIN_BLOCKS - 1), M // (MIN_BLOCKS - 1))
    tests = judge_effects(design, ['real'], design.fit(['real']), blocks, block_s=1.0)
    assert not tests['real'].judged
    assert np.isnan(tests['real'].p_value)


def test_a_joint_the_effects_make_worse_falls_back_and_untouched_joints_do_not(problem) -> None:
    design, blocks = problem
    final = design.fit(['real', 'spurious'])
    assert fallback_joints(design, final, blocks) == [1]
    assert fallback_joints(design, design.fit(['real']), blocks) == []  # joint 1 untouched


def test_a_fallback_joint_gets_the_nominal_torque_online_and_offline(mabi) -> None:
    rng = np.random.default_rng(11)
    terms = [
        (EffectSpec('coulomb_friction', j, mabi.joints[j], {'smoothing_velocity': 0.01}),
         np.array([40.0 + j]))
        for j in range(6)
    ]  # fmt: skip
    model = AugmentedModel(mabi, 'motor', terms, nominal_joints=['joint_2', 'joint_5'])
    full = AugmentedModel(mabi, 'motor', terms)
    q, v, a = (rng.uniform(-1.0, 1.0, (8, 6)) for _ in range(3))
    nominal = model.nominal.evaluate(q, v, a).tau_nominal
    tau = model.torque(q, v, a)
    np.testing.assert_allclose(tau[:, [1, 4]], nominal[:, [1, 4]], rtol=1e-12)
    np.testing.assert_allclose(tau[:, [0, 2, 3, 5]], full.torque(q, v, a)[:, [0, 2, 3, 5]])
    one = model.sample_function()
    for k in range(len(q)):
        np.testing.assert_allclose(one(q[k], v[k], a[k]), tau[k], rtol=1e-12, atol=1e-9)
    again = AugmentedModel.from_dict(model.to_dict(), mabi)
    assert again.nominal_joints == ('joint_2', 'joint_5')
    with pytest.raises(RobotModelError, match=r"nominal_joints \['wrist'\]"):
        AugmentedModel(mabi, 'motor', terms, nominal_joints=['wrist'])
