"""Stribeck humps of other shapes: the law and the twin's true robot (forms the diagnosis must
meet on real machines)."""

from __future__ import annotations

import numpy as np
import pytest

from id_learning.errors import ConfigError
from id_learning.physics.friction import STRIBECK_SHAPES, stribeck
from id_learning.twin.effects import effects_from_dict

JOINTS = ('j1', 'j2')


def test_every_shape_is_a_hump_that_fades_from_its_level_at_rest():
    v = np.array([0.0, 0.03, 0.3, -0.03])
    for shape in STRIBECK_SHAPES:
        hump = stribeck(v, 0.03, 1e-9, shape) * np.sign(v)
        assert hump[1] == pytest.approx(hump[3])  # even in v
        assert 1.0 > hump[1] > hump[2] > 0.0
    expected = {'gaussian': np.exp(-1.0), 'exponential': np.exp(-1.0), 'lorentzian': 0.5}
    for shape, value in expected.items():  # at v = v_s
        assert stribeck(0.03, 0.03, 1e-9, shape) == pytest.approx(value)
    assert stribeck(0.06, 0.03, 1e-9, 'gaussian') == pytest.approx(np.exp(-4.0))
    assert stribeck(0.06, 0.03, 1e-9, 'exponential') == pytest.approx(np.exp(-2.0))
    with pytest.raises(ValueError, match='unknown Stribeck shape'):
        stribeck(v, 0.03, 0.005, 'cubic')


@pytest.mark.parametrize('shape', STRIBECK_SHAPES)
def test_the_twin_gives_its_hump_the_shape_its_config_names(shape):
    section = {'enabled': True, 'level': [0.0, 50.0], 'velocity': [0.02, 0.02], 'shape': shape}
    effects = effects_from_dict({'stribeck_friction': section}, JOINTS)
    hump = effects.effects['stribeck_friction']
    v = np.array([[0.0, 0.01], [0.0, -0.05]])
    np.testing.assert_allclose(hump.torque(v), 50.0 * stribeck(v, 0.02, 0.005, shape) * [0, 1])
    assert hump.to_dict()['shape'] == shape


def test_a_twin_hump_of_an_unknown_shape_is_refused_naming_the_known_ones():
    section = {'enabled': True, 'level': [0.0, 50.0], 'shape': 'cubic'}
    with pytest.raises(ConfigError, match=r'effects.stribeck_friction.shape.*gaussian'):
        effects_from_dict({'stribeck_friction': section}, JOINTS)
