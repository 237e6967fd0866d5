"""Where the package's shipped files are: a source checkout, or a colcon/ament install."""

from __future__ import annotations

from pathlib import Path

from id_learning.errors import ConfigError

__all__ = ['default_bag', 'default_robot_config', 'share_dir']

PACKAGE = 'id_learning'


def share_dir() -> Path:
    """The folder holding config/ (and bags/ in a checkout).

    Raises:
        ConfigError: neither a checkout nor an ament install is found.
    """
    checkout = Path(__file__).resolve().parents[2]
    if (checkout / 'config').is_dir() and (checkout / 'package.xml').is_file():
        return checkout
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:
        raise ConfigError(
            'cannot find the id_learning config folder (no checkout, no ament index)'
        ) from None
    try:
        return Path(get_package_share_directory(PACKAGE))
    except (PackageNotFoundError, OSError) as err:
        raise ConfigError(f'cannot find the id_learning share folder: {err}') from err


def default_robot_config() -> Path:
    """The shipped MABI MAX 100 robot config."""
    return share_dir() / 'config' / 'mabi_max100.yaml'


def default_bag() -> Path:
    """The shipped default twin recording."""
    return share_dir() / 'bags' / 'default'
