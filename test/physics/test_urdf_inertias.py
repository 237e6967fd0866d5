"""URDF links refused when no rigid body can have their mass or inertia, naming the link."""

from __future__ import annotations

from pathlib import Path

import pytest

from id_learning.errors import RobotModelError
from id_learning.physics.rigid_body import check_link_inertias

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ('old', 'new', 'message'),
    [
        ('<mass value="150"/>', '<mass value="-150"/>', r'link link_3: mass -150\.0 kg'),
        (
            'ixx="4.9964" ixy="0" ixz="-1.0061333" iyy="7.07"',
            'ixx="1.0" ixy="0" ixz="0" iyy="1.0"',
            r'link link_3: principal moments .* not those of a rigid body',
        ),
        ('ixx="4.9964"', 'ixx="-4.9964"', 'link link_3: principal moments'),
    ],
    ids=['negative-mass', 'triangle-inequality', 'negative-moment'],
)
def test_a_urdf_link_no_rigid_body_can_have_is_refused_naming_it(
    tmp_path: Path, old: str, new: str, message: str
) -> None:
    text = (REPO / 'urdf/mabi_max100.urdf').read_text()
    assert text.count(old) == 1
    urdf = tmp_path / 'bad.urdf'
    urdf.write_text(text.replace(old, new))
    with pytest.raises(RobotModelError, match=message) as err:
        check_link_inertias(urdf)
    assert str(urdf) in str(err.value)
    check_link_inertias(REPO / 'urdf/mabi_max100.urdf')  # the real one passes
