"""Where a robot config's ``urdf`` points: a path, or one of three kinds of URL.

The forms (``URDF_FORMS``, named in every refusal):

- a path, relative to the robot config's folder, or absolute;
- ``file:///absolute/path.urdf`` (RFC 8089: an absolute path, on this host);
- ``example-robot-data://<robot>_description/urdf/<file>.urdf``: a file of the
  example-robot-data package (pip's cmeel prefix, a ROS install, robotpkg's /opt/openrobots);
- ``package://<package>/<path>``: a file in a ROS package's share folder, found as
  ``ament_index_python.get_package_share_directory`` finds it: the first prefix of
  ``AMENT_PREFIX_PATH`` whose ament resource index
  (``share/ament_index/resource_index/packages/<package>``) lists the package. The index is
  plain files, so it is read here without ROS: it works wherever a ROS 2 workspace is sourced
  and the package is installed, and says so where none is.

A path inside a package may not leave it (``..``, an absolute path, a link out of it): the
package is where it is looked for, and a config that reaches elsewhere through it is refused.
Any other scheme (``http://``, ``s3://``) is refused: the URDF is read from this machine.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path, PurePosixPath
from urllib.parse import unquote, urlsplit

from id_learning.config_io import not_a_file
from id_learning.errors import ConfigError

__all__ = ['EXAMPLE_ROBOT_DATA_SCHEME', 'PACKAGE_SCHEME', 'URDF_FORMS', 'resolve_urdf']

EXAMPLE_ROBOT_DATA_SCHEME = 'example-robot-data://'
PACKAGE_SCHEME = 'package://'
#: The forms a robot config's ``urdf`` takes, as every refusal names them.
URDF_FORMS = (
    'a path (relative to the robot config, or absolute), file:///absolute/path.urdf, '
    'example-robot-data://<robot>_description/urdf/<file>.urdf or '
    'package://<ros_package>/<path> (found through AMENT_PREFIX_PATH, a sourced ROS 2 workspace)'
)
#: ``scheme://`` (RFC 3986 scheme characters), or ``file:`` with a single slash.
_URL = re.compile(r'^(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://|^(?P<file>file):', re.IGNORECASE)
#: Where an ament prefix lists its packages (ament_index_python's resource type 'packages').
_PACKAGE_INDEX = Path('share/ament_index/resource_index/packages')


def _refuse(where: str, value: str, problem: str) -> ConfigError:
    return ConfigError(f'{where}: urdf {value!r}: {problem}; the urdf may be {URDF_FORMS}')


def resolve_urdf(value: str, base_dir: Path, where: str = 'robot config') -> Path:
    """Resolve a config's ``urdf`` entry to an existing file (the module docstring's forms).

    Args:
        value: the ``urdf`` entry.
        base_dir: folder of the config file (a relative path is read there).
        where: the config file, named in errors.

    Returns:
        The absolute path of the URDF.

    Raises:
        ConfigError: an unknown scheme; a path leaving its package; no ROS package index for
            ``package://``; the package or the file missing; a folder or device, not a file.
            Each names the value, what is wrong, and the forms a ``urdf`` takes.
    """
    found = _URL.match(value)
    scheme = None if found is None else (found['scheme'] or found['file']).lower()
    if scheme is None:
        path = Path(value) if Path(value).is_absolute() else base_dir / value
    elif scheme == 'file':
        path = _file_url(value, where)
    elif scheme == 'example-robot-data' and value.startswith(EXAMPLE_ROBOT_DATA_SCHEME):
        path = _in_example_robot_data(value, where)
    elif scheme == 'package' and value.startswith(PACKAGE_SCHEME):
        path = _in_ros_package(value, where)
    else:
        raise _refuse(where, value, f'the scheme {scheme}:// is not one the urdf is read from')
    kind = not_a_file(path)
    if kind is not None and not kind.startswith('a FIFO'):  # a FIFO is read as it comes
        raise _refuse(where, value, f'{path}: {kind}, not a URDF file')
    return path.resolve()


def _file_url(value: str, where: str) -> Path:
    """The absolute path of a ``file:`` URL on this host."""
    parts = urlsplit(value)
    if parts.netloc not in ('', 'localhost'):
        raise _refuse(where, value, f'a file on another host ({parts.netloc}) cannot be read')
    if parts.query or parts.fragment:
        raise _refuse(where, value, 'a file URL with a query or fragment names no file')
    path = unquote(parts.path)
    if not path.startswith('/'):
        raise _refuse(where, value, 'a file URL holds an absolute path (file:///dir/robot.urdf)')
    return Path(path)


def _inside(value: str, relative: str, package: str, where: str) -> PurePosixPath:
    """``relative`` as a path that stays in its package (no ``..``, not absolute)."""
    inner = PurePosixPath(relative)
    if not relative or inner.is_absolute() or '..' in inner.parts:
        raise _refuse(
            where, value, f'{relative!r} leaves the {package} package (an absolute path or ..); '
            'a path inside a package stays in it: give the file itself as a path instead',
        )  # fmt: skip
    return inner


def _within(candidate: Path, root: Path) -> bool:
    """Whether ``candidate``, links followed, lies inside ``root``."""
    return candidate.resolve().is_relative_to(root.resolve())


def _example_robot_data_roots() -> list[Path]:
    """Folders where the example-robot-data package keeps its robots (pip/cmeel, apt, robotpkg)."""
    roots = [Path(entry) / 'cmeel.prefix/share/example-robot-data/robots' for entry in sys.path]
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            roots.append(Path(prefix) / 'share/example-robot-data/robots')
    roots += [Path('/opt/openrobots/share/example-robot-data/robots')]
    return [root for root in roots if root.is_dir()]


def _in_example_robot_data(value: str, where: str) -> Path:
    inner = _inside(value, value[len(EXAMPLE_ROBOT_DATA_SCHEME) :], 'example-robot-data', where)
    roots = _example_robot_data_roots()
    for root in roots:
        candidate = root / inner
        if candidate.is_file() and _within(candidate, root):
            return candidate
    raise _refuse(
        where, value, f'not found in the example-robot-data package (searched {roots or "none"}); '
        'install it with `pip install example-robot-data` or `apt install '
        'ros-jazzy-example-robot-data`',
    )  # fmt: skip


def _in_ros_package(value: str, where: str) -> Path:
    package, _, relative = value[len(PACKAGE_SCHEME) :].partition('/')
    if not package:
        raise _refuse(where, value, 'package:// names no package (package://<package>/<path>)')
    inner = _inside(value, relative, package, where)
    prefixes = [entry for entry in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
                if entry]  # fmt: skip
    if not prefixes:
        raise _refuse(
            where, value, 'package:// needs a ROS package index, and AMENT_PREFIX_PATH is empty: '
            'source ROS 2 (/opt/ros/jazzy/setup.bash) or the workspace that installs '
            f'{package}, or give the file itself as a path',
        )  # fmt: skip
    prefix = next((Path(p) for p in prefixes if (Path(p) / _PACKAGE_INDEX / package).is_file()),
                  None)  # fmt: skip
    if prefix is None:
        raise _refuse(
            where, value, f'the ROS package {package!r} is not in the package index of '
            f'AMENT_PREFIX_PATH ({os.pathsep.join(prefixes)}): install it (apt install '
            f"ros-jazzy-{package.replace('_', '-')}) and source its setup, or give the file "
            'itself as a path',
        )  # fmt: skip
    share = prefix / 'share' / package
    candidate = share / inner
    if not candidate.is_file() or not _within(candidate, share):
        raise _refuse(where, value, f'no file {inner} in the ROS package {package!r} ({share})')
    return candidate
