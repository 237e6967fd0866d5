"""What an artifact's metadata must say to load: tampered metadata is refused, naming the field.

Property tests draw tampered metadata (a scaler with a zero-width, inverted or wrong-length entry;
a physical parameter below its bound; a key given twice in a JSON object) and check each is
refused, and that the untampered one passes. The end-to-end tests edit real (tiny) artifacts and
write the artifact hash again, as a careful hand would: the hash then proves nothing, and the
checks must still refuse.
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import quick_preprocess, sine_recording

from id_learning import __version__
from id_learning.errors import CheckpointError, DatasetError
from id_learning.models import metadata_checks
from id_learning.models.artifact import (
    METADATA_FILE,
    WEIGHTS_FILE,
    document_digest,
    read_artifact,
    write_artifact,
)
from id_learning.models.metadata_checks import (
    PHYSICAL_SIGNS,
    DuplicateKeyError,
    check_physical_parameters,
    check_scalers,
    check_targets,
    loads_unique,
)
from id_learning.models.physics import RneaLqConfig, RneaLqModel
from id_learning.models.registry import load_model

PATH = Path('run/models/x/model.json')
#: Scaler fields of a model.json and the quantities (columns per joint) each scales.
SCALER_FIELDS = {
    ('fitted', 'input_scaler'): 3,
    ('fitted', 'state_scaler'): 2,
    ('fitted', 'target_scaler'): 1,
    ('fitted', 'residual_scaler'): 1,
    ('fitted', 'scaling', 'position'): 1,
    ('fitted', 'scaling', 'velocity'): 1,
    ('fitted', 'scaling', 'torque'): 1,
    ('target_scaler',): 1,
}


def _joints(n: int) -> tuple[str, ...]:
    return tuple(f'joint_{i}' for i in range(1, n + 1))


def _nest(path: tuple[str, ...], value: object) -> dict:
    out: dict = {path[-1]: value}
    for key in reversed(path[:-1]):
        out = {key: out}
    return out


@st.composite
def scalers(draw):
    """(field path, joints, low, high): a valid scaler of one of the known fields."""
    path = draw(st.sampled_from(sorted(SCALER_FIELDS)))
    joints = _joints(draw(st.integers(1, 7)))
    size = SCALER_FIELDS[path] * len(joints)
    finite = st.floats(-1e4, 1e4, allow_nan=False)
    low = np.array(draw(st.lists(finite, min_size=size, max_size=size)))
    width = np.array(draw(st.lists(st.floats(1e-3, 1e4), min_size=size, max_size=size)))
    return path, joints, low, low + width


@given(scalers())
def test_a_valid_scaler_of_every_field_passes(case):
    path, joints, low, high = case
    check_scalers(_nest(path, {'low': low.tolist(), 'high': high.tolist()}), PATH, joints)


@given(scalers(), st.sampled_from(['zero', 'inverted']), st.data())
def test_a_scaler_with_a_zero_width_or_inverted_entry_is_refused_naming_field_and_index(
    case, tamper, data
):
    path, joints, low, high = case
    k = data.draw(st.integers(0, len(low) - 1))
    high[k] = low[k] if tamper == 'zero' else low[k] - data.draw(st.floats(1e-3, 1e3))
    metadata = _nest(path, {'low': low.tolist(), 'high': high.tolist()})
    with pytest.raises(CheckpointError) as err:
        check_scalers(metadata, PATH, joints)
    message = str(err.value)
    assert str(PATH) in message
    assert '.'.join(path) in message
    assert f'at index {k} ' in message
    assert ('zero width' if tamper == 'zero' else 'high below low') in message
    # The column is named by quantity and joint.
    assert f'of {joints[k % len(joints)]})' in message


@given(scalers(), st.sampled_from(['low', 'high']), st.sampled_from([-1, 1]), st.data())
def test_a_scaler_entry_of_the_wrong_length_is_refused_naming_field_length_and_expected(
    case, name, change, data
):
    path, joints, low, high = case
    values = {'low': low.tolist(), 'high': high.tolist()}
    if change < 0:
        values[name].pop(data.draw(st.integers(0, len(low) - 1)))
    else:
        values[name].append(values[name][-1] + 1.0)
    with pytest.raises(CheckpointError) as err:
        check_scalers(_nest(path, values), PATH, joints)
    field = '.'.join(path)
    assert f'{field}.{name} has {len(low) + change} values, expected {len(low)}' in str(err.value)


@pytest.mark.parametrize(
    ('scaler', 'match'),
    [
        ({'low': [0.0, 1.0]}, 'is not a scaler'),
        ({'low': [0.0, 'x'], 'high': [1.0, 2.0]}, r'low is not a list of numbers'),
        ({'low': 0.0, 'high': 1.0}, r'low is not a list of numbers'),
    ],
)
def test_a_malformed_scaler_is_refused_naming_it(scaler, match):
    with pytest.raises(CheckpointError, match=match):
        check_scalers({'fitted': {'input_scaler': scaler}}, PATH, _joints(2))


# -- physical parameters -------------------------------------------------------------------------
SIGNED = sorted(
    (kind, name)
    for kind, signs in PHYSICAL_SIGNS.items()
    for name, (_, _, bound, inclusive) in signs.items()
    if bound == 0.0 and inclusive
)


@given(
    st.sampled_from(SIGNED),
    st.integers(1, 7),
    st.data(),
)
def test_any_negative_dissipative_coefficient_or_inertia_is_refused_naming_joint_and_value(
    signed, n, data
):
    kind, name = signed
    joints = _joints(n)
    values = np.array(data.draw(st.lists(st.floats(0.0, 1e3), min_size=n, max_size=n)))
    tensors = {name: values.copy()}
    check_physical_parameters(kind, tensors, PATH, joints)  # zero and above pass
    j = data.draw(st.integers(0, n - 1))
    values[j] = -data.draw(st.floats(1e-2, 1e6))
    with pytest.raises(CheckpointError) as err:
        check_physical_parameters(kind, {name: values}, PATH, joints)
    message = str(err.value)
    assert f'({name}) of {joints[j]} is {values[j]:.6g}' in message
    assert 'non-physical' in message
    if 'friction' in name or name == 'viscous' or name == 'coulomb':
        assert 'injects energy' in message


def test_every_parameter_out_of_its_range_is_named_in_one_line():
    tensors = {
        'rotor_inertia_motor_side': np.array([0.01, -0.094, 0.01]),
        'viscous': np.array([-835.0, -3928.0, 10.0]),
        'coulomb': np.zeros(3),
    }
    with pytest.raises(CheckpointError) as err:
        check_physical_parameters('rnea_lq', tensors, PATH, _joints(3))
    message = str(err.value)
    assert '\n' not in message
    assert 'rotor inertia (rotor_inertia_motor_side) of joint_2 is -0.094 kg*m^2' in message
    assert 'viscous friction (viscous) of joint_1 is -835 N*m*s/rad' in message
    assert '2 joints so' in message


def test_a_value_a_solver_leaves_just_below_zero_passes_and_the_other_bounds_hold():
    joints = _joints(3)
    check_physical_parameters(
        'rnea_id', {'friction.viscous': np.array([100.0, -1e-9, 0.0])}, PATH, joints
    )
    with pytest.raises(CheckpointError, match=r'Stribeck velocity .* of joint_2 is 0 rad/s'):
        check_physical_parameters(
            'rnea_id', {'stribeck_velocity': np.array([0.1, 0.0, 0.1])}, PATH, joints
        )
    with pytest.raises(CheckpointError, match=r'label gain \(physics.gain\) of joint_3 is -1'):
        check_physical_parameters(
            'rnea_id_mlp', {'physics.gain': np.array([0.0, 0.1, -1.0])}, PATH, joints
        )
    theta = np.zeros(30)
    theta[10] = -2.0  # the second body's mass
    with pytest.raises(CheckpointError, match=r'body 1 has mass -2 kg'):
        check_physical_parameters('rnea_id', {'theta': theta}, PATH, joints)
    # Kinds without signed parameters pass whatever their tensors hold.
    check_physical_parameters('mlp', {'viscous': -np.ones(3)}, PATH, joints)


# -- duplicate keys ------------------------------------------------------------------------------
KEYS = st.text('abcdefgh_', min_size=1, max_size=6)
SCALARS = st.none() | st.booleans() | st.integers(-1000, 1000) | st.text('xyz ', max_size=4)


def _json_object(pairs: list) -> str:
    return '{' + ', '.join(f'{json.dumps(k)}: {v}' for k, v in pairs) + '}'


@st.composite
def objects_with_a_duplicate(draw, depth: int = 0):
    """(JSON text with one key twice in one of its objects, that key)."""
    keys = draw(st.lists(KEYS, min_size=1, max_size=5, unique=True))
    pairs = [[key, json.dumps(draw(SCALARS))] for key in keys]
    if depth < 3 and draw(st.booleans()):  # the duplicate in a nested object
        inner, key = draw(objects_with_a_duplicate(depth + 1))
        pairs[draw(st.integers(0, len(pairs) - 1))][1] = inner
        return _json_object(pairs), key
    key = draw(st.sampled_from(keys))
    pairs.insert(draw(st.integers(0, len(pairs))), [key, json.dumps(draw(SCALARS))])
    return _json_object(pairs), key


@given(objects_with_a_duplicate())
def test_a_key_given_twice_in_any_object_is_refused_naming_it(case):
    text, key = case
    with pytest.raises(DuplicateKeyError, match=f'key {key!r} appears twice'):
        loads_unique(text)


@given(st.dictionaries(KEYS, st.dictionaries(KEYS, SCALARS) | SCALARS))
def test_json_with_unique_keys_reads_as_the_standard_parser_reads_it(document):
    text = json.dumps(document)
    assert loads_unique(text) == json.loads(text)


# -- targets and versions ------------------------------------------------------------------------
def test_targets_that_disagree_are_refused_naming_both_fields():
    check_targets({'preprocessing': {'target': 'joint'}, 'fitted': {'target': 'joint'}}, PATH)
    with pytest.raises(
        CheckpointError,
        match=r"preprocessing\.target is 'motor' but fitted\.physics\.target is 'joint'",
    ):
        check_targets(
            {'preprocessing': {'target': 'motor'}, 'fitted': {'physics': {'target': 'joint'}}},
            PATH,
        )
    with pytest.raises(CheckpointError, match=r"fitted\.target is 'both', not one of"):
        check_targets({'fitted': {'target': 'both'}}, PATH)


@pytest.mark.parametrize(
    ('version', 'warned'), [('99.0.0', True), (__version__, False), ('0.0.1', False)]
)
def test_an_artifact_from_a_newer_version_is_warned_of_naming_both(caplog, version, warned):
    with caplog.at_level(logging.WARNING, logger=metadata_checks.__name__):
        metadata_checks.check_version({'package_version': version}, PATH)
    text = caplog.text
    assert (f'id_learning {version}, newer than this id_learning {__version__}' in text) == warned


# -- end to end: tiny artifacts, edited and rehashed ---------------------------------------------
@pytest.fixture(scope='module')
def tiny(tmp_path_factory, mabi):
    from predictor.tiny_artifacts import build_tiny_artifacts

    return build_tiny_artifacts(tmp_path_factory.mktemp('tiny'), mabi, ['rnea_lq', 'mlp'])


def _edited(tiny: dict[str, Path], kind: str, tmp_path: Path, edit, weights=None) -> Path:
    """A copy of a tiny artifact with model.json (and the weights) edited, hashes written again."""
    import hashlib

    from safetensors.numpy import load_file, save_file

    folder = tmp_path / kind
    shutil.copytree(tiny[kind], folder)
    meta = folder / METADATA_FILE
    document = json.loads(meta.read_text())
    if weights is not None:
        tensors = weights(load_file(str(folder / WEIGHTS_FILE)))
        save_file(tensors, str(folder / WEIGHTS_FILE))
        document['weights_sha256'] = hashlib.sha256(
            (folder / WEIGHTS_FILE).read_bytes()
        ).hexdigest()
    edit(document)
    document['artifact_sha256'] = document_digest(document)
    meta.write_text(json.dumps(document, indent=1))
    return folder


def test_the_tiny_artifacts_load(tiny, mabi):
    for kind, folder in tiny.items():
        assert load_model(folder, mabi, kind).kind == kind


def test_a_model_json_with_a_key_twice_is_refused_naming_file_and_key(tiny, mabi, tmp_path):
    folder = _edited(tiny, 'mlp', tmp_path, lambda d: None)
    meta = folder / METADATA_FILE
    meta.write_text(meta.read_text().replace('"kind": "mlp",', '"kind": "lstm",\n "kind": "mlp",'))
    with pytest.raises(CheckpointError) as err:
        read_artifact(folder, mabi)
    assert str(meta) in str(err.value)
    assert '\'kind\' appears twice in one object ("lstm" and "mlp")' in str(err.value)


def test_a_rehashed_degenerate_or_short_scaler_is_refused_naming_the_field(tiny, mabi, tmp_path):
    def degenerate(d):
        d['fitted']['input_scaler']['high'] = list(d['fitted']['input_scaler']['low'])

    folder = _edited(tiny, 'mlp', tmp_path / 'a', degenerate)
    with pytest.raises(CheckpointError, match=r'fitted\.input_scaler has zero width at index 0 '
                       r'\(q of joint_1\)'):  # fmt: skip
        load_model(folder, mabi)
    folder = _edited(
        tiny, 'mlp', tmp_path / 'b', lambda d: d['fitted']['input_scaler']['low'].pop()
    )
    with pytest.raises(
        CheckpointError,
        match=r'fitted\.input_scaler\.low has 17 values, expected 18 \(q, v, a of each of 6 ',
    ):
        load_model(folder, mabi)


def test_rehashed_negative_viscous_friction_is_refused_naming_joint_and_value(
    tiny, mabi, tmp_path
):
    def negative(tensors):
        tensors['viscous'] = np.array([10.0, 10.0, -250.0, 10.0, 10.0, 10.0])
        return tensors

    folder = _edited(tiny, 'rnea_lq', tmp_path, lambda d: None, weights=negative)
    with pytest.raises(
        CheckpointError,
        match=r'rnea_lq is non-physical: viscous friction \(viscous\) of joint_3 is -250 '
        r'N\*m\*s/rad \(must be >= 0, friction below zero injects energy\)',
    ):
        load_model(folder, mabi)


def test_a_model_loaded_for_a_run_of_another_target_is_refused_naming_both(tiny, mabi, tmp_path):
    folder = _edited(tiny, 'mlp', tmp_path, lambda d: d.update(preprocessing={'target': 'joint'}))
    assert load_model(folder, mabi, target='joint').kind == 'mlp'
    with pytest.raises(
        CheckpointError,
        match=r"predicts the 'joint' torque, but the run's preprocessing\.target is 'motor'",
    ):
        load_model(folder, mabi, target='motor')


def test_a_newer_packages_artifact_loads_with_one_warning_naming_both_versions(
    tiny, mabi, tmp_path, caplog
):
    folder = _edited(tiny, 'mlp', tmp_path, lambda d: d.update(package_version='99.0.0'))
    with caplog.at_level(logging.WARNING):
        load_model(folder, mabi)
    warned = [r for r in caplog.records if 'newer than this id_learning' in r.getMessage()]
    assert len(warned) == 1
    assert '99.0.0' in warned[0].getMessage()
    assert __version__ in warned[0].getMessage()


def test_nothing_is_written_that_a_load_would_refuse(tmp_path, mabi):
    fitted = {'input_scaler': {'low': [0.0] * 18, 'high': [1.0] * 17 + [0.0]}}
    with pytest.raises(CheckpointError, match=r'zero width at index 17 \(a of joint_6\)'):
        write_artifact(tmp_path / 'm', 'mlp', mabi, {'w': np.zeros(2)}, settings={}, fitted=fitted)
    assert not (tmp_path / 'm').exists()


# -- fits that would write what a load refuses ----------------------------------------------------
def test_rnea_lq_holds_a_negative_coefficient_at_zero_and_says_so(mabi, caplog):
    rng = np.random.default_rng(0)
    regressor = rng.normal(size=(500, 2)) * [1.0, 30.0]
    names = ['rotor_inertia_motor_side', 'viscous']
    model = RneaLqModel(RneaLqConfig(), mabi)
    positive = regressor @ [0.5, 2.0]
    np.testing.assert_allclose(model._solve(regressor, positive, names, 0), [0.5, 2.0])
    # Far beyond the noise, and most of the label: a finding (test_physics_signed.py has the
    # negative estimates that are noise, or too small to matter, held quietly).
    negative = regressor @ [-0.5, 0.02] + 0.01 * rng.normal(size=500)
    with caplog.at_level(logging.WARNING):
        theta = model._solve(regressor, negative, names, 1)
    assert theta[0] == 0.0
    assert theta[1] > 0
    assert 'joint_2: least squares put rotor_inertia_motor_side at -0.49' in caplog.text
    assert '(a negative inertia; t = -' in caplog.text
    # A column that is zero on the training rows (a joint that never moved) gets zero.
    regressor[:, 0] = 0.0
    assert model._solve(regressor, positive, names, 0)[0] == 0.0


@settings(max_examples=20)
@given(st.lists(st.floats(-100.0, 100.0), min_size=3, max_size=3), st.integers(0, 2**16))
def test_rnea_lq_never_fits_a_coefficient_a_load_would_refuse(mabi, truth, seed):
    rng = np.random.default_rng(seed)
    regressor = rng.normal(size=(200, 3))
    names = ['rotor_inertia_motor_side', 'viscous', 'offset']
    theta = RneaLqModel(RneaLqConfig(friction='viscous_coulomb_offset'), mabi)._solve(
        regressor, regressor @ truth + rng.normal(size=200), names, 0
    )
    assert (theta[:2] >= 0).all()


def test_a_fit_on_a_joint_that_never_moved_is_refused_naming_it(mabi):
    from dataclasses import replace

    from id_learning.dataset import prepare_dataset
    from id_learning.models.data import TrainingData

    recording = sine_recording(1250)
    position, velocity = recording.position.copy(), recording.velocity.copy()
    position[:, 3], velocity[:, 3] = 0.2, 0.0
    frozen = replace(recording, position=position, velocity=velocity)
    data = TrainingData(prepare_dataset(frozen, mabi, quick_preprocess()), mabi)
    with pytest.raises(DatasetError, match=r'mlp: q of joint_4, v of joint_4, a of joint_4 never'):
        data.require_varied('mlp')
    data.require_varied('rnea_lq', inputs=False)  # stores no input ranges
