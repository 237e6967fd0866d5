"""package.xml names every runtime requirement, so that rosdep installs what the package needs."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

from support import REPO

#: Runtime requirements whose rosdep key is not python3-<name> or python3-<name>-pip.
ROSDEP_KEYS = {
    'pin': 'pinocchio',  # the PyPI wheel of pinocchio; ROS ships the library as pinocchio
    'pyyaml': 'python3-yaml',
}
#: Installed outside requirements.txt (pinned in tools/bootstrap_venv.sh), needed all the same.
OUTSIDE_REQUIREMENTS = ('torch',)


def runtime_requirements() -> list[str]:
    """The distribution names in requirements.txt before its '# Tests' section, normalised."""
    names = []
    for line in (REPO / 'requirements.txt').read_text(encoding='utf-8').splitlines():
        if line.startswith('# Tests'):
            break
        requirement = line.split('#', 1)[0].strip()
        if requirement:
            name = re.match(r'[A-Za-z0-9][A-Za-z0-9._-]*', requirement)
            assert name is not None, line
            names.append(re.sub(r'[-_.]+', '-', name.group(0)).lower())
    return names


def exec_depends() -> set[str]:
    root = ET.parse(REPO / 'package.xml').getroot()
    return {
        (item.text or '').strip() for tag in ('exec_depend', 'depend') for item in root.iter(tag)
    }


def test_every_runtime_requirement_has_an_exec_depend_in_package_xml():
    requirements = runtime_requirements()
    assert {'numpy', 'pin', 'cvxpy', 'optuna', 'psycopg'} <= set(requirements)
    assert 'pytest' not in requirements  # the test section is left out
    declared = exec_depends()
    missing = []
    for name in [*requirements, *OUTSIDE_REQUIREMENTS]:
        keys = {ROSDEP_KEYS[name]} if name in ROSDEP_KEYS else {f'python3-{name}'}
        keys |= {f'{key}-pip' for key in keys}
        if not keys & declared:
            missing.append(f'{name} (as one of {sorted(keys)})')
    assert not missing, f'package.xml has no exec_depend for: {", ".join(missing)}'


def test_the_test_requirements_are_test_depends():
    root = ET.parse(REPO / 'package.xml').getroot()
    tests = {(item.text or '').strip() for item in root.iter('test_depend')}
    assert {'python3-pytest', 'python3-hypothesis'} <= tests
