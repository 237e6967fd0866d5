"""load_robot_config: the shipped configs, and every validation error path on edited copies."""

from __future__ import annotations

import hashlib
import re
import shutil
from dataclasses import FrozenInstanceError, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from id_learning.errors import ConfigError
from id_learning.robot import RobotConfig, load_robot_config

REPO = Path(__file__).resolve().parents[2]
ROBOT_NAMES = ('mabi_max100', 'ur5', 'panda')
EXPECTED_JOINTS = {
    'mabi_max100': tuple(f'joint_{i}' for i in range(1, 7)),
    'ur5': (
        'shoulder_pan_joint',
        'shoulder_lift_joint',
        'elbow_joint',
        'wrist_1_joint',
        'wrist_2_joint',
        'wrist_3_joint',
    ),
    'panda': tuple(f'panda_joint{i}' for i in range(1, 8)),
}
STUDY_DEFAULT_CUTOFF_HZ = [1.2, 0.3, 0.3, 0.7, 0.5, 0.7]


# -- the shipped configs -------------------------------------------------------------------------
@pytest.mark.parametrize(('name', 'n_joints'), [('mabi_max100', 6), ('ur5', 6), ('panda', 7)])
def test_shipped_config_loads_with_its_joint_count(name: str, n_joints: int) -> None:
    path = REPO / 'config' / f'{name}.yaml'
    config = load_robot_config(path)

    assert config.name == name
    assert config.n_joints == n_joints
    assert config.joints == EXPECTED_JOINTS[name]
    assert config.urdf_path.is_file()
    assert config.urdf_path.is_absolute()
    assert config.source == path.resolve()
    for array in (
        config.drives.gear_ratio,
        config.drives.torque_constant,
        config.drives.rotor_inertia,
        config.limits.position_lower,
        config.limits.position_upper,
        config.limits.velocity,
        config.limits.acceleration,
        config.limits.torque,
        config.lowpass_cutoff_hz,
    ):
        assert array.shape == (n_joints,)
        assert array.dtype == np.float64


def test_mabi_config_reads_the_values_written_in_the_yaml(
    robot_configs: dict[str, RobotConfig],
) -> None:
    config = robot_configs['mabi_max100']

    assert config.urdf_path == (REPO / 'urdf/mabi_max100.urdf').resolve()
    assert config.payload_frame == 'flange'
    assert config.ipo_period_s == 0.008
    assert config.locked_joints == {}
    np.testing.assert_array_equal(
        config.drives.gear_ratio, [205.0, 220.0, 185.0, 121.0, 112.0, 81.0]
    )
    np.testing.assert_array_equal(
        config.limits.position_lower, [-3.0, -1.35, -2.55, -5.1, -2.05, -5.9]
    )
    assert config.topics.joint_states == '/joint_states'
    assert config.topics.motor_currents == '/motor_currents'


def test_panda_config_locks_both_fingers_at_zero(robot_configs: dict[str, RobotConfig]) -> None:
    assert robot_configs['panda'].locked_joints == {
        'panda_finger_joint1': 0.0,
        'panda_finger_joint2': 0.0,
    }


def test_scalar_value_is_broadcast_to_every_joint(
    robot_configs: dict[str, RobotConfig], write_config: Any
) -> None:
    ur5 = robot_configs['ur5']  # gear_ratio: 101.0, velocity: 3.1
    np.testing.assert_array_equal(ur5.drives.gear_ratio, np.full(6, 101.0))
    np.testing.assert_array_equal(ur5.limits.velocity, np.full(6, 3.1))

    edited = load_robot_config(
        write_config('panda', set={'drives.torque_constant': 0.5, 'lowpass_cutoff_hz': 3})
    )
    np.testing.assert_array_equal(edited.drives.torque_constant, np.full(7, 0.5))
    np.testing.assert_array_equal(edited.lowpass_cutoff_hz, np.full(7, 3.0))


def test_config_arrays_and_fields_are_read_only(robot_configs: dict[str, RobotConfig]) -> None:
    config = robot_configs['mabi_max100']
    with pytest.raises(ValueError, match='read-only'):
        config.drives.gear_ratio[0] = 1.0
    with pytest.raises(ValueError, match='read-only'):
        config.limits.velocity[0] = 1.0
    with pytest.raises(FrozenInstanceError):
        config.name = 'other'  # type: ignore[misc]


def test_relative_topic_names_are_the_root_namespace_full_names(write_config: Any) -> None:
    path = write_config(
        'mabi_max100', {'topics': {'joint_states': 'arm/joint_states', 'motor_currents': '/i'}}
    )

    topics = load_robot_config(path).topics

    assert (topics.joint_states, topics.motor_currents) == ('/arm/joint_states', '/i')


@pytest.mark.parametrize('topic', ['~/joint_states', '{node}/joint_states'])
def test_topic_names_that_depend_on_a_node_are_refused(write_config: Any, topic: str) -> None:
    path = write_config('mabi_max100', {'topics': {'joint_states': topic}})

    with pytest.raises(ConfigError, match=r'topics\.joint_states: .* depends on a node name'):
        load_robot_config(path)


def test_urdf_sha256_is_the_hash_of_the_urdf_bytes(robot_configs: dict[str, RobotConfig]) -> None:
    for config in robot_configs.values():
        expected = hashlib.sha256(config.urdf_path.read_bytes()).hexdigest()
        assert config.urdf_sha256() == expected


def test_a_urdf_checked_out_with_crlf_line_ends_is_the_same_robot(
    robot_configs: dict[str, RobotConfig], tmp_path: Path
) -> None:
    # Probe 16 (C65): git's core.autocrlf made the shipped URDF another robot for every model.
    config = robot_configs['mabi_max100']
    crlf = tmp_path / config.urdf_path.name
    crlf.write_bytes(config.urdf_path.read_bytes().replace(b'\n', b'\r\n'))
    assert b'\r\n' in crlf.read_bytes()
    assert replace(config, urdf_path=crlf).urdf_sha256() == config.urdf_sha256()
    edited = tmp_path / 'edited.urdf'
    edited.write_bytes(config.urdf_path.read_bytes().replace(b'<robot', b'<robot ', 1))
    assert replace(config, urdf_path=edited).urdf_sha256() != config.urdf_sha256()


def test_unedited_copy_loads_like_the_original(
    robot_configs: dict[str, RobotConfig], write_config: Any
) -> None:
    # Precondition for every error-path test below: the copy itself is valid.
    for name in ROBOT_NAMES:
        copy = load_robot_config(write_config(name))
        original = robot_configs[name]
        assert copy.joints == original.joints
        assert copy.urdf_path == original.urdf_path
        np.testing.assert_array_equal(copy.limits.torque, original.limits.torque)


def test_relative_urdf_path_is_taken_from_the_yaml_folder_not_the_cwd(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / 'robot'
    folder.mkdir()
    shutil.copy(REPO / 'urdf/mabi_max100.urdf', folder / 'arm.urdf')
    data = yaml.safe_load((REPO / 'config/mabi_max100.yaml').read_text(encoding='utf-8'))
    data['urdf'] = 'arm.urdf'
    (folder / 'arm.yaml').write_text(yaml.safe_dump(data), encoding='utf-8')
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)

    config = load_robot_config(folder / 'arm.yaml')

    assert config.urdf_path == (folder / 'arm.urdf').resolve()


# -- validation errors ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ('name', 'edits', 'match'),
    [
        pytest.param('mabi_max100', {'set': {'colour': 'red'}}, r'colour', id='unknown-top-key'),
        pytest.param(
            'mabi_max100', {'set': {'drives.backlash': 0.1}}, r'backlash', id='unknown-drive-key'
        ),
        pytest.param(
            'mabi_max100', {'set': {'limits.jerk': 10.0}}, r'jerk', id='unknown-limit-key'
        ),
        pytest.param(
            'mabi_max100', {'set': {'topics.imu': '/imu'}}, r'imu', id='unknown-topic-key'
        ),
        *[
            pytest.param('mabi_max100', {'delete': [key]}, re.escape(f"['{key}']"), id=key)
            for key in ('name', 'urdf', 'joints', 'drives', 'limits', 'ipo_period_s')
        ],
        pytest.param(
            'mabi_max100', {'delete': ['payload_frame']}, r'payload_frame', id='payload_frame'
        ),
        pytest.param(
            'mabi_max100',
            {'delete': ['drives.rotor_inertia']},
            r'drives.*rotor_inertia',
            id='missing-drive-key',
        ),
        pytest.param(
            'ur5',
            {'delete': ['limits.torque']},
            r'limits.*missing.*torque',
            id='missing-limit-key',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'drives.torque_constant': [2.0] * 5}},
            r'drives\.torque_constant: expected 6 values',
            id='short-vector',
        ),
        pytest.param(
            'panda',
            {'set': {'limits.velocity': [2.0] * 8}},
            r'limits\.velocity: expected 7 values',
            id='long-vector',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'lowpass_cutoff_hz': [[1.0] * 6]}},
            r'lowpass_cutoff_hz: expected 6 values',
            id='matrix-instead-of-vector',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'drives.gear_ratio': [205.0, 220.0, 0.0, 121.0, 112.0, 81.0]}},
            r'drives\.gear_ratio: every value must be >',
            id='zero-gear-ratio',
        ),
        pytest.param(
            'ur5',
            {'set': {'drives.gear_ratio': -101.0}},
            r'drives\.gear_ratio: every value must be >',
            id='negative-gear-ratio',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'drives.torque_constant': 0.0}},
            r'drives\.torque_constant',
            id='zero-torque-constant',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'drives.rotor_inertia': [3.5e-3, 3.5e-3, -1e-6, 6.4e-4, 6.4e-4, 2.9e-4]}},
            r'drives\.rotor_inertia: every value must be >=',
            id='negative-rotor-inertia',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'drives.gear_ratio': [205.0, 'fast', 185.0, 121.0, 112.0, 81.0]}},
            r'drives\.gear_ratio: expected numbers',
            id='non-numeric',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'limits.torque': [9000.0, float('nan'), 7500.0, 1600.0, 1300.0, 650.0]}},
            r'limits\.torque: values must be finite',
            id='nan',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'limits.position_lower': [-3.0, -1.35, 1.25, -5.1, -2.05, -5.9]}},
            r'position_lower must be below position_upper \(joint joint_3\)',
            id='lower-equals-upper',
        ),
        pytest.param(
            'panda',
            {'set': {'limits.position_upper': [2.9, 1.7, 2.9, -0.1, 2.9, -0.5, 2.9]}},
            r'position_lower must be below position_upper \(joint panda_joint6\)',
            id='lower-above-upper',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'limits.acceleration': [3.0, 2.5, 3.0, 6.0, 0.0, 9.0]}},
            r'limits\.acceleration',
            id='zero-acceleration-limit',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'lowpass_cutoff_hz': [1.2, 0.3, 0.3, 0.7, 0.5, 62.5]}},
            r'lowpass_cutoff_hz must be below the Nyquist frequency 62.5 Hz',
            id='cutoff-at-nyquist',
        ),
        pytest.param(
            'panda',
            {'set': {'lowpass_cutoff_hz': [2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 900.0]}},
            r'lowpass_cutoff_hz must be below the Nyquist frequency 500 Hz',
            id='cutoff-above-nyquist',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'lowpass_cutoff_hz': 0.0}},
            r'lowpass_cutoff_hz: every value must be >',
            id='zero-cutoff',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'ipo_period_s': 0.0}},
            r'ipo_period_s must be in',
            id='zero-ipo-period',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'ipo_period_s': '8 ms'}},
            r'ipo_period_s must be in',
            id='ipo-period-as-text',
        ),
        pytest.param(
            'mabi_max100',
            {
                'set': {
                    'joints': ['joint_1', 'joint_2', 'joint_3', 'joint_4', 'joint_2', 'joint_6']
                }
            },
            r"joints: duplicate joint names \['joint_2'\]",
            id='duplicate-joints',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'joints': []}},
            r'joints: expected a non-empty list',
            id='no-joints',
        ),
        pytest.param(
            'mabi_max100', {'set': {'joints': 'joint_1'}}, r'joints: expected', id='joints-as-text'
        ),
        pytest.param(
            'panda',
            {'set': {'locked_joints': {'panda_joint7': 0.0}}},
            r"locked_joints \['panda_joint7'\] are also listed in joints",
            id='locked-and-actuated',
        ),
        pytest.param(
            'panda',
            {'set': {'locked_joints': {'panda_finger_joint1': 'open'}}},
            r'locked_joints: expected a mapping',
            id='locked-position-as-text',
        ),
        pytest.param('mabi_max100', {'set': {'name': ''}}, r'name must be', id='empty-name'),
        pytest.param(
            'mabi_max100',
            {'set': {'drives': [1, 2]}},
            r'drives: expected a mapping',
            id='drives-list',
        ),
        pytest.param(
            'mabi_max100',
            {'set': {'limits': 3.0}},
            r'limits: expected a mapping',
            id='limits-scalar',
        ),
    ],
)
def test_invalid_config_raises_config_error_naming_file_and_key(
    write_config: Any, name: str, edits: dict[str, Any], match: str
) -> None:
    path = write_config(name, **edits)

    with pytest.raises(ConfigError, match=match) as excinfo:
        load_robot_config(path)

    assert str(path) in str(excinfo.value)


def test_cutoff_just_below_nyquist_is_accepted(write_config: Any) -> None:
    path = write_config(
        'mabi_max100',
        set={'lowpass_cutoff_hz': [1.2, 0.3, 0.3, 0.7, 0.5, 62.4]},
        delete=['input_smoothing_hz'],
    )

    robot = load_robot_config(path)

    assert robot.lowpass_cutoff_hz[5] == 62.4
    # The default input smoothing lies between a label cut-off that high and Nyquist.
    assert 62.4 < robot.input_smoothing_hz[5] < 62.5
    np.testing.assert_array_equal(robot.input_smoothing_hz[:5], 10.0)


def test_input_smoothing_defaults_to_10_hz_and_is_per_joint(write_config: Any) -> None:
    default = load_robot_config(write_config('mabi_max100', delete=['input_smoothing_hz']))
    given = load_robot_config(
        write_config('mabi_max100', set={'input_smoothing_hz': [5, 6, 7, 8, 9, 10]})
    )

    np.testing.assert_array_equal(default.input_smoothing_hz, np.full(6, 10.0))
    np.testing.assert_array_equal(given.input_smoothing_hz, [5, 6, 7, 8, 9, 10])


@pytest.mark.parametrize(
    ('value', 'match'),
    [
        (0.3, 'must lie above the label cut-offs'),
        (62.5, 'below the Nyquist frequency'),
        (-1.0, 'input_smoothing_hz'),
    ],
)
def test_input_smoothing_outside_label_cutoff_and_nyquist_is_refused(
    write_config: Any, value: float, match: str
) -> None:
    path = write_config('mabi_max100', set={'input_smoothing_hz': value})

    with pytest.raises(ConfigError, match=match) as excinfo:
        load_robot_config(path)

    assert 'input_smoothing_hz' in str(excinfo.value)


def test_zero_rotor_inertia_is_accepted(write_config: Any) -> None:
    path = write_config('mabi_max100', set={'drives.rotor_inertia': 0.0})

    np.testing.assert_array_equal(load_robot_config(path).drives.rotor_inertia, np.zeros(6))


def test_missing_urdf_file_is_refused_naming_the_urdf(tmp_path: Path, write_config: Any) -> None:
    missing = tmp_path / 'no_such_robot.urdf'
    path = write_config('mabi_max100', set={'urdf': str(missing)})

    with pytest.raises(ConfigError, match=r'urdf .*no_such_robot\.urdf.*no such file'):
        load_robot_config(path)


def test_relative_urdf_missing_next_to_the_yaml_is_refused(write_config: Any) -> None:
    path = write_config('mabi_max100', set={'urdf': '../urdf/mabi_max100.urdf'})

    # Relative to the copy's folder (tmp_path), where no urdf/ folder exists.
    with pytest.raises(ConfigError, match=r"urdf '\.\./urdf/mabi_max100\.urdf'"):
        load_robot_config(path)


def test_unknown_example_robot_data_path_is_refused_with_install_hint(write_config: Any) -> None:
    path = write_config(
        'ur5', set={'urdf': 'example-robot-data://ur_description/urdf/ur99_robot.urdf'}
    )

    with pytest.raises(
        ConfigError, match=r'urdf .*ur99_robot\.urdf.*not found in the example-robot-data package'
    ) as excinfo:
        load_robot_config(path)

    assert 'pip install example-robot-data' in str(excinfo.value)


def test_seven_joint_config_without_cutoff_is_refused(write_config: Any) -> None:
    path = write_config('panda', delete=['lowpass_cutoff_hz'])

    with pytest.raises(ConfigError, match=r'lowpass_cutoff_hz is required for a 7-joint robot'):
        load_robot_config(path)


def test_six_joint_config_without_cutoff_gets_the_study_default(write_config: Any) -> None:
    # ur5 states 2.0 Hz everywhere, so the default can only come from the loader.
    path = write_config('ur5', delete=['lowpass_cutoff_hz'])

    config = load_robot_config(path)

    np.testing.assert_array_equal(config.lowpass_cutoff_hz, STUDY_DEFAULT_CUTOFF_HZ)


def test_study_default_cutoff_is_still_checked_against_nyquist(write_config: Any) -> None:
    # A 0.5 s IPO period puts Nyquist at 1 Hz, below the study's 1.2 Hz on axis 1.
    path = write_config('ur5', set={'ipo_period_s': 0.5}, delete=['lowpass_cutoff_hz'])

    with pytest.raises(ConfigError, match=r'below the Nyquist frequency 1 Hz'):
        load_robot_config(path)


def test_unreadable_or_non_mapping_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='cannot read config file'):
        load_robot_config(tmp_path / 'absent.yaml')
    listing = tmp_path / 'list.yaml'
    listing.write_text('- joint_1\n- joint_2\n', encoding='utf-8')
    with pytest.raises(ConfigError, match='expected a mapping at the top level'):
        load_robot_config(listing)
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: [unclosed\n', encoding='utf-8')
    with pytest.raises(ConfigError, match='not valid YAML'):
        load_robot_config(broken)


def test_how_two_robots_differ_names_name_order_and_joints(
    robot_configs: dict[str, RobotConfig],
) -> None:
    from dataclasses import replace

    from id_learning.robot.config import how_robots_differ

    mabi = robot_configs['mabi_max100']
    assert how_robots_differ(mabi, mabi) == ''
    swapped = replace(mabi, joints=(mabi.joints[1], mabi.joints[0], *mabi.joints[2:]))
    assert how_robots_differ(mabi, swapped).startswith('the same joints in another order')
    fewer = replace(mabi, name='other', joints=mabi.joints[:5])
    text = how_robots_differ(mabi, fewer)
    assert text.startswith("robot 'other', not 'mabi_max100'")
    assert f"lacks ['{mabi.joints[5]}']" in text
