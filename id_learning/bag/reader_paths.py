"""Where a bag's storage files are, and what a folder that is no bag holds.

rosbag2 resolves each ``relative_file_paths`` entry of metadata.yaml against the bag folder, so
``data/base_0.mcap`` is a file in the subfolder ``data``. rosbags, which reads the bags here,
keeps only each entry's file name and looks for it in the bag folder itself. For a bag that
lists files in subfolders, the reader is given a view: a temporary folder holding a copy of
metadata.yaml that lists the files by name, and a link to each file where it is. Nothing of the
bag is changed.

A folder without metadata.yaml is either a torn recording (``.mcap`` files: ``bag recover``
rebuilds it) or no recording at all, which messages say plainly (a train run, an evaluation)
instead of sending the user to ``bag recover``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path, PurePath

import yaml
from rosbags.rosbag2 import Reader

from id_learning.bag.metadata_file import load_metadata
from id_learning.bag.reader_storage import listed_files
from id_learning.errors import BagError
from id_learning.output_kinds import KINDS, folder_holds

__all__ = ['BagReader', 'folder_is_no_bag', 'listed_paths', 'storage_files', 'subfolder_view']

#: What the view's folder names begin with (in the system's temporary folder).
VIEW_PREFIX = 'id_learning-bag-view-'


def listed_paths(path: Path) -> list[tuple[str, Path]]:
    """(entry as metadata.yaml lists it, the file it names in the bag folder), in list order."""
    return [(entry, path / PurePath(entry)) for entry in listed_files(path)]


def storage_files(path: Path) -> tuple[str, ...]:
    """The storage files a bag's reader reads, relative to the bag folder, for reports.

    The entries metadata.yaml lists where it can be read, else the ``.mcap``/``.db3`` files in
    the folder.
    """
    listed = tuple(PurePath(entry).as_posix() for entry in listed_files(path))
    if listed:
        return listed
    return tuple(sorted(p.name for p in path.iterdir() if p.suffix in {'.mcap', '.db3'}))


def subfolder_view(path: Path) -> tempfile.TemporaryDirectory[str] | None:
    """A view of a bag that lists storage files in subfolders, for rosbags; None when none does.

    The view (removed when the returned object is cleaned up or collected) holds metadata.yaml
    with each entry by its file name, and a link to each listed file.

    Raises:
        BagError: a listed file is missing, two entries share a file name, or the view cannot
            be made (the OS's reason).
    """
    entries = listed_paths(path)
    if all(PurePath(entry).name == entry for entry, _ in entries):
        return None
    missing = [entry for entry, file in entries if not file.is_file()]
    if missing:
        raise BagError(
            f'{path}: metadata.yaml lists {", ".join(missing)}, which the folder does not hold '
            f'(relative_file_paths are read relative to {path})'
        )
    names = [PurePath(entry).name for entry, _ in entries]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise BagError(
            f'{path}: metadata.yaml lists several storage files named {", ".join(twice)} (in '
            'different subfolders); the reader takes files by name: rename them apart'
        )
    try:
        document = load_metadata(path)
        info = document['rosbag2_bagfile_information']
        info['relative_file_paths'] = names
        for item in info.get('files') or []:
            if isinstance(item, dict) and 'path' in item:
                item['path'] = PurePath(str(item['path'])).name
    except (yaml.YAMLError, KeyError, TypeError) as err:  # BagError names the file itself
        raise BagError(f'{path / "metadata.yaml"}: cannot be read ({err})') from err
    view = tempfile.TemporaryDirectory(prefix=VIEW_PREFIX)
    try:
        folder = Path(view.name)
        (folder / 'metadata.yaml').write_text(
            yaml.safe_dump(document, sort_keys=False), encoding='utf-8'
        )
        for name, (_, file) in zip(names, entries, strict=True):
            (folder / name).symlink_to(file.resolve())
    except OSError as err:
        view.cleanup()
        raise BagError(
            f'{path}: cannot read the storage files metadata.yaml lists in subfolders '
            f'({err.strerror or err}, making a view in {view.name}); move them into {path} and '
            'list them by name'
        ) from err
    return view


def folder_is_no_bag(path: Path) -> str | None:
    """Why a folder without metadata.yaml is no recording at all, or None (it may be torn).

    None when it holds ``.mcap`` files (``bag recover`` may rebuild it); otherwise what it holds,
    named by its files: a result of this package (a train run, an evaluation) or other files.
    """
    try:
        if any(p.suffix == '.mcap' for p in path.iterdir()):
            return None
        holding = folder_holds(path)
        nested = sorted(p.relative_to(path).as_posix() for p in path.glob('*/*.mcap'))
    except OSError:
        return None
    if nested:
        return (
            f'no metadata.yaml and no .mcap file in the folder itself ({", ".join(nested[:3])} '
            'lie in subfolders): not a recording; pass the folder that holds the .mcap files'
        )
    if holding.kind in KINDS:
        return (
            f'holds {holding.describe()}, not a recording (no metadata.yaml, no .mcap file): '
            'pass a bag folder'
        )
    return f'not a recording: no metadata.yaml and no .mcap file (it holds {holding.describe()})'


class BagReader(Reader):
    """rosbags' Reader, owning the view a bag with subfolders is read through (``subfolder_view``).

    The view is removed when the reader closes, or when opening it fails.
    """

    def __init__(self, path: Path) -> None:
        self.view = subfolder_view(path)
        super().__init__(Path(self.view.name) if self.view else path)

    def drop_view(self) -> None:
        """Remove the view (if any); the reader reads nothing more."""
        if self.view is not None:
            self.view.cleanup()
            self.view = None

    def close(self) -> None:
        """Close the storage files, then remove the view."""
        try:
            super().close()
        finally:
            self.drop_view()
