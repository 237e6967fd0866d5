"""The twin config's ``effects``: every nesting level refused with the key path when misshapen."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from id_learning.errors import ConfigError
from id_learning.twin import effects_from_dict, load_twin_config

JOINTS = ('joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_5', 'joint_6')
REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ('effects', 'match'),
    [
        (['viscous_friction'], r'effects: expected a mapping of effect name to settings'),
        ('viscous_friction', r'effects: expected a mapping of effect name to settings'),
        ({'viscous_friction': ['enabled']}, r'effects\.viscous_friction: expected a mapping'),
        ({'viscous_friction': 0}, r'effects\.viscous_friction: expected a mapping'),
        ({'viscous_friction': {'enabled': 'yes'}}, r'viscous_friction\.enabled: expected true'),
        ({'gravity_spring': {'joint': ['joint_2']}}, r'gravity_spring\.joint: expected a joint'),
        ({1: {}}, r'unknown effect'),
    ],
)
def test_a_misshapen_effects_section_is_a_config_error(effects: object, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        effects_from_dict(effects, JOINTS)


def test_absent_effects_are_all_disabled() -> None:
    assert effects_from_dict(None, JOINTS).enabled_names() == []
    assert effects_from_dict({}, JOINTS).enabled_names() == []


def test_a_list_of_effects_in_a_config_file_names_the_file(tmp_path: Path) -> None:
    data = yaml.safe_load((REPO / 'config' / 'twin_default.yaml').read_text(encoding='utf-8'))
    data['effects'] = ['viscous_friction']
    data['robot'] = str(REPO / 'config' / 'mabi_max100.yaml')
    path = tmp_path / 'twin.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    with pytest.raises(ConfigError, match=r'twin\.yaml: effects: expected a mapping'):
        load_twin_config(path)
