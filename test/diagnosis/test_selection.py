"""Forward selection, alias sets and the noise-level stop on small synthetic designs."""

from __future__ import annotations

import numpy as np
import pytest

from id_learning.diagnosis.aliases import find_aliases
from id_learning.diagnosis.design import Design
from id_learning.diagnosis.selection import forward_select

M, N = 400, 2


def design_with(y_signal: np.ndarray, columns: dict[str, np.ndarray], seed: int = 0) -> Design:
    """A design whose train/test parts are the two halves of the rows, unit noise per sample."""
    rng = np.random.default_rng(seed)
    y = y_signal + rng.standard_normal(y_signal.shape)
    half = len(y) // 2
    split = {'train': slice(0, half), 'test': slice(half, None)}
    return Design(
        {part: y[rows] for part, rows in split.items()},
        {label: {part: x[rows] for part, rows in split.items()} for label, x in columns.items()},
        np.ones(N),
        {part: np.full(N, float(len(y[rows]))) for part, rows in split.items()},
    )


def on_joint(x: np.ndarray, joint: int) -> np.ndarray:
    out = np.zeros((len(x), N, 1))
    out[:, joint, 0] = x
    return out


def always_plausible(design, fit):
    return dict.fromkeys(fit.groups, (True, ''))


@pytest.fixture
def signals():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 20, 2 * M)
    return {
        'a': on_joint(np.sin(t), 0),
        'a_copy': on_joint(np.sin(t), 0),
        'c': on_joint(rng.standard_normal(2 * M), 1),
        'd': on_joint(np.cos(3 * t), 1),
    }


def test_two_identical_candidates_form_an_alias_set(signals):
    design = design_with(3.0 * signals['a'][:, :, 0], signals)
    labels = list(signals)
    selection = forward_select(design, labels, always_plausible)
    assert len(selection.selected) == 1
    assert selection.selected[0] in ('a', 'a_copy')
    aliases = find_aliases(design, selection.selected, labels, always_plausible)
    assert len(aliases) == 1
    assert set(aliases[0].members) == {'a', 'a_copy'}
    other = next(m for m in aliases[0].members if m != aliases[0].representative)
    assert aliases[0].canonical_correlation[other] == pytest.approx(1.0)


def test_distinct_candidates_are_no_aliases(signals):
    columns = {k: signals[k] for k in ('a', 'c', 'd')}
    design = design_with(3.0 * signals['a'][:, :, 0] + 2.0 * signals['d'][:, :, 0], columns)
    selection = forward_select(design, list(columns), always_plausible)
    assert sorted(selection.selected) == ['a', 'd']
    assert find_aliases(design, selection.selected, list(columns), always_plausible) == []


def test_the_selection_resumes_from_groups_already_selected(signals):
    columns = {k: signals[k] for k in ('a', 'c', 'd')}
    design = design_with(3.0 * signals['a'][:, :, 0] + 2.0 * signals['d'][:, :, 0], columns)
    resumed = forward_select(design, list(columns), always_plausible, start=['a'])
    assert resumed.selected == ['a', 'd']
    assert [step.label for step in resumed.steps] == ['d']  # the new group's step only
    # The groups it starts from count towards the maximum.
    full = forward_select(design, list(columns), always_plausible, start=['a'], max_groups=1)
    assert full.selected == ['a']
    assert full.stop_reason == 'reached the maximum number of effects'


def test_pure_noise_selects_nothing(signals):
    columns = {k: signals[k] for k in ('a', 'c', 'd')}
    design = design_with(np.zeros((2 * M, N)), columns, seed=5)
    selection = forward_select(design, list(columns), always_plausible)
    assert selection.selected == []
    assert selection.rejected is not None
    assert selection.rejected.p_value > selection.level


def test_an_implausible_value_keeps_a_significant_candidate_out(signals):
    design = design_with(-3.0 * signals['a'][:, :, 0], {'a': signals['a']})

    def positive_only(design_, fit):
        return {g: (bool(design_.physical(fit, g)[0] >= 0), 'must be >= 0') for g in fit.groups}

    selection = forward_select(design, ['a'], positive_only)
    assert selection.selected == []
    assert selection.rejected is not None
    assert selection.rejected.p_value < 1e-10
    assert 'must be >= 0' in selection.rejected.reason


def test_fit_recovers_the_coefficient_with_an_honest_interval(signals):
    design = design_with(3.0 * signals['a'][:, :, 0], {'a': signals['a']})
    fit = design.fit(['a'])
    theta = design.physical(fit, 'a')[0]
    sd = float(np.sqrt(design.physical_covariance(fit, 'a')[0, 0]))
    assert abs(theta - 3.0) < 4 * sd
    assert 0.01 < sd < 0.2


def test_an_alias_set_ranks_its_alternatives_and_names_the_closest_two():
    from id_learning.diagnosis.aliases import AliasSet

    alias = AliasSet(
        'a',
        ['a', 'd', 'b', 'c', 'e'],
        unexplained={'b': 0.5, 'c': 0.1, 'd': 2.0, 'e': 0.3},
    )
    assert alias.alternatives() == ['c', 'e', 'b', 'd']
    assert alias.summary().startswith('a or c or e (+2 more that mimic it less closely')
    assert AliasSet('a', ['a', 'b'], unexplained={'b': 0.0}).summary() == 'a or b'
    # A result keeps the closest alternatives and counts the others.
    short = alias.closest(2)
    assert short.members == ['a', 'c', 'e']
    assert short.further == 2
    assert set(short.unexplained) == {'c', 'e'}
    assert short.summary() == alias.summary()
    assert short.closest(1).further == 3


def test_the_block_sandwich_matches_white_noise_and_grows_with_a_correlated_misfit(signals):
    x = signals['c']  # white regressor on joint 1
    design = design_with(2.0 * x[:, :, 0], {'c': x}, seed=3)
    fit = design.fit(['c'])
    blocks = np.arange(M) // 10  # 40 blocks of 10 training rows
    model = design.physical_covariance(fit, 'c')[0, 0]
    sandwich = design.sandwich_covariance(fit, blocks)[0, 0] / design.column_norm[0] ** 2
    assert sandwich == pytest.approx(model, rel=0.35)

    # A misfit that moves with the regressor's sign inside each block (a wrong form, not noise)
    # leaves the noise-based covariance as is and widens the sandwich.
    rng = np.random.default_rng(4)
    flips = np.repeat(rng.choice([-1.0, 1.0], 2 * M // 10), 10)
    misfit = 1.5 * flips * x[:, 1, 0]
    biased = design_with(2.0 * x[:, :, 0] + np.stack([0 * misfit, misfit], 1), {'c': x}, seed=3)
    fit = biased.fit(['c'])
    model = biased.physical_covariance(fit, 'c')[0, 0]
    sandwich = biased.sandwich_covariance(fit, blocks)[0, 0] / biased.column_norm[0] ** 2
    assert sandwich > 1.5 * model


def test_a_candidate_that_fits_as_well_in_the_kept_ones_place_is_an_alias():
    """A balancer-like group of three columns explains the data; a one-column scale (which also
    scales a term the data lack) was kept. The balancer cannot reproduce the scale's own torque,
    but in its place it fits both parts as well: an alias where the swap is allowed."""
    t = np.linspace(0, 20, 2 * M)
    columns = {
        'scale': on_joint(np.sin(t) + 0.1 * np.sin(5 * t), 0),
        'spring': np.stack([on_joint(f, 0)[:, :, 0] for f in (np.sin(t), np.cos(2 * t), t)], -1),
        'other': on_joint(np.cos(3 * t), 0),
    }
    design = design_with(3.0 * columns['spring'][:, :, 0], columns)
    labels = list(columns)

    def always(a: str, b: str) -> bool:
        return True

    assert find_aliases(design, ['scale'], labels, always_plausible) == []
    (alias,) = find_aliases(design, ['scale'], labels, always_plausible, swappable=always)
    assert alias.members == ['scale', 'spring']  # 'other' fits far worse in its place
    # The spring fits better, but its two extra columns are charged: a little is left.
    assert 0.0 <= alias.unexplained['spring'] < 2.0
    assert 0.9 < alias.canonical_correlation['spring'] < 1.0


def test_a_pooled_fit_is_least_squares_on_every_row_with_the_prior_kept(signals):
    """The held-out part chooses the effects; the pooled design reads their values from both
    parts: the same values as weighted least squares on all rows, variance shrunk by the share."""
    x = np.concatenate([signals['a'], signals['d']], axis=2)  # one group of two columns
    truth = np.array([3.0, -2.0])
    design = design_with(x @ truth, {'ad': x}, seed=5)
    pooled = design.pooled()
    fit = pooled.fit(['ad'])
    y = np.concatenate([design.y['train'], design.y['test']]).reshape(-1)
    reference = np.linalg.lstsq(x.reshape(-1, 2), y, rcond=None)[0]
    assert pooled.physical(fit, 'ad') == pytest.approx(reference, rel=1e-9)
    half = design.physical_covariance(design.fit(['ad']), 'ad').diagonal()
    assert pooled.physical_covariance(fit, 'ad').diagonal() == pytest.approx(half / 2, rel=0.3)
    assert pooled.n_eff_train == pytest.approx(2 * design.n_eff_train)
    # The held-out part itself is unchanged; a prior still pulls towards zero.
    assert pooled.fit(['ad']).rss['test'] == pytest.approx(
        float(np.sum((design.y['test'] - x[M:] @ pooled.physical(fit, 'ad')) ** 2)), rel=1e-9
    )
    shrunk = pooled.with_priors({'ad': np.eye(2) * 1e4}).fit(['ad'])
    assert np.all(np.abs(pooled.physical(shrunk, 'ad')) < 0.1 * np.abs(truth))
    assert design.y['train'].shape == (M, N)  # the design pooled from is left as it was


def test_a_pooled_fit_takes_the_held_out_parts_nuisances_out_as_the_training_part_did(signals):
    """A torque held at a rest in the held-out part (a standstill's: no function of motion) is
    projected off the held-out rows before they join the fit, as the training part's rests are."""
    x = signals['a']
    design = design_with(3.0 * x[:, :, 0], {'a': x}, seed=6)
    box = np.zeros(M)
    box[100:180] = 1.0
    basis = (box / np.linalg.norm(box))[:, None]
    held = design.y['test'].copy()
    held[:, 0] += 40.0 * box  # the rest's torque, on the joint 'a' lives on
    columns = {'a': {'train': x[:M], 'test': x[M:]}}
    rested = Design({'train': design.y['train'], 'test': held}, columns, np.ones(N),
                    design.n_effective)  # fmt: skip

    def project(v: np.ndarray) -> np.ndarray:
        out = np.array(v, dtype=float, copy=True)
        out[:, 0] -= basis @ (basis.T @ out[:, 0])
        return out

    pooled = rested.pooled(project, np.array([1.0, 0.0]))
    fit = pooled.fit(['a'])
    rows = np.concatenate([x[:M].reshape(-1), project(x[M:]).reshape(-1)])
    y = np.concatenate([design.y['train'].reshape(-1), project(held).reshape(-1)])
    assert pooled.physical(fit, 'a')[0] == pytest.approx(rows @ y / (rows @ rows), rel=1e-9)
    sd = float(np.sqrt(pooled.physical_covariance(fit, 'a')[0, 0]))
    assert abs(pooled.physical(fit, 'a')[0] - 3.0) < 4 * sd
    naive = rested.pooled()  # the rest's torque taken for the effect's
    assert abs(naive.physical(naive.fit(['a']), 'a')[0] - 3.0) > 10 * sd
    assert pooled.n_effective['train'] == pytest.approx(
        design.n_effective['train'] + design.n_effective['test'] - [1.0, 0.0]
    )


def test_a_group_with_other_columns_fits_as_a_design_built_anew(signals):
    """``rss_with`` updates one group's Gram blocks; the fit must equal one built from scratch,
    a prior on the group included (its precision follows the new columns' norms)."""
    rng = np.random.default_rng(4)
    y = 2.0 * signals['a'][:, :, 0] + 0.5 * signals['d'][:, :, 0]
    other = 3.0 * signals['c'] + 0.2 * rng.standard_normal(signals['c'].shape)
    base = design_with(y, signals)
    base = base.with_priors({'c': np.array([[4.0]])})
    replaced = {**signals, 'c': other}
    fresh = design_with(y, replaced).with_priors({'c': np.array([[4.0]])})
    groups = ['a', 'c', 'd']
    half = len(y) // 2
    columns = {'train': other[:half], 'test': other[half:]}
    rss = base.rss_with(groups, 'c', columns)
    expected = fresh.fit(groups).rss
    for part in ('train', 'test'):
        assert rss[part] == pytest.approx(expected[part], rel=1e-9)
    assert rss['train'] != pytest.approx(base.fit(groups).rss['train'], rel=1e-6)


def _chopped(t: np.ndarray, pieces: int = 3) -> dict[str, np.ndarray]:
    """sin(t) cut into ``pieces`` interleaved parts: each explains 1/pieces of it."""
    part = np.floor(t * 3).astype(int) % pieces
    return {f'part{k}': on_joint(np.sin(t) * (part == k), 0) for k in range(pieces)}


def refusing(*labels: str):
    def check(design, fit):
        return {
            g: (g not in labels, 'beyond its bound' if g in labels else '') for g in fit.groups
        }

    return check


def test_a_refused_candidate_that_fits_a_joint_closes_it_to_stand_ins():
    t = np.linspace(0, 20, 2 * M)
    columns = {'true': on_joint(np.sin(t), 0), **_chopped(t), 'd': on_joint(np.cos(3 * t), 1)}
    design = design_with(3.0 * np.sin(t)[:, None] * [1, 0] + 2.0 * columns['d'][:, :, 0], columns)
    # Without the joint known, the stand-ins fill joint 0 with three wrong names.
    blind = forward_select(design, list(columns), refusing('true'))
    assert {'part0', 'part1', 'part2'} <= set(blind.selected)
    selection = forward_select(design, list(columns), refusing('true'), joint_of=_joint(columns))
    assert selection.selected == ['d']
    assert list(selection.refused) == [0]
    assert selection.refused[0].label == 'true'
    assert 'beyond its bound' in selection.refused[0].reason


def test_a_refused_candidate_closes_its_joint_only_once_it_fits_what_is_left():
    t = np.linspace(0, 20, 2 * M)
    columns = {'true': on_joint(np.sin(t), 0), **_chopped(t), 'e': on_joint(np.cos(3 * t), 0)}
    design = design_with(3.0 * columns['true'][:, :, 0] + 4.0 * columns['e'][:, :, 0], columns)
    selection = forward_select(design, list(columns), refusing('true'), joint_of=_joint(columns))
    assert selection.selected == ['e']  # the plausible effect enters first, then it closes
    assert list(selection.refused) == [0]


def test_a_refused_candidate_no_better_on_its_joint_than_a_robot_wide_one_closes_nothing():
    """A payload reaches every joint: what it explains on a joint is no form the library lacks."""
    t = np.linspace(0, 20, 2 * M)
    wide = on_joint(np.sin(t), 0) + on_joint(np.cos(2 * t), 1)
    columns = {'wide': wide, 'true': on_joint(np.sin(t), 0), **_chopped(t)}
    design = design_with(3.0 * wide[:, :, 0], columns)
    on_one = _joint({k: v for k, v in columns.items() if k != 'wide'})
    selection = forward_select(
        design,
        list(columns),
        refusing('true'),
        joint_of=lambda label: None if label == 'wide' else on_one(label),
    )
    assert selection.selected == ['wide']
    assert selection.refused == {}


def test_a_refused_candidate_no_better_than_a_plausible_one_closes_nothing(signals):
    design = design_with(3.0 * signals['a'][:, :, 0], signals)
    selection = forward_select(design, list(signals), refusing('a_copy'), joint_of=_joint(signals))
    assert selection.selected == ['a']
    assert selection.refused == {}


def _joint(columns: dict[str, np.ndarray]):
    """joint_of for single-joint columns: the joint whose column is not zero."""
    return lambda label: int(np.flatnonzero(np.abs(columns[label]).sum(axis=(0, 2)))[0])
