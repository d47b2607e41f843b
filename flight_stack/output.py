"""The output folder of a run, written so that nothing earlier is lost.

A run writes into a staging folder beside its target (``OUT.incomplete-XXXXXXXX``, on the same file
system) and :meth:`RunOutput.commit` moves the finished run into place in one step (a rename when
``OUT`` does not exist yet). So:

* an earlier run in ``OUT`` is refused unless ``overwrite`` (and with it, its run files are replaced
  only once the new run has finished writing; other files in ``OUT`` are left alone);
* a run that does not finish (interrupted, a node died, an error) leaves ``OUT`` as it was; what it
  wrote (a closed bag, say) stays in the staging folder, which :meth:`RunOutput.keep_partial` names;
* a flight that fails its checks (``flight_ok`` false) is a finished run: it is committed.

A bag given outside ``OUT`` (``--bag``) is a second target, staged and committed the same way.

Two runs into one ``OUT`` at once: :meth:`RunOutput.create` takes an exclusive lock on
``.OUT_NAME.lock`` beside ``OUT`` (see :mod:`flight_stack.locking`) and holds it until the run is
committed or kept as partial, so the second run is refused by name (ParameterError) before it
flies, and never replaces the first one's result. Holding that lock, a run knows that every other
``OUT.incomplete-*`` folder is a leftover of a run that ended: it removes the empty ones and names
the others (:attr:`RunOutput.leftovers`), which the command prints.
"""
from __future__ import annotations

import os
import secrets
import shutil
from pathlib import Path

from quad_msgs_bridge.validation import ParameterError

from .locking import FileLock

#: what a run writes into its output folder (and what --overwrite replaces)
RUN_ENTRIES = ('summary.json', 'review.json', 'report.html', 'report.md', 'plots', 'bag')
STAGING_MARK = '.incomplete-'
_BAG_FILES = ('metadata.yaml',)


def _absolute(path: Path) -> Path:
    """``path`` made absolute, '..' and '.' resolved by name (symbolic links are kept)."""
    return Path(os.path.abspath(path))


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _check_writable_parent(option: str, target: Path) -> None:
    """The folder that will hold ``target`` is (or can be created as) a writable directory."""
    base = _nearest_existing(_absolute(target).parent)
    if not base.is_dir():
        raise ParameterError(f'{option}: {base} is not a directory, so {target} cannot be created')
    if not os.access(base, os.W_OK | os.X_OK):
        raise ParameterError(f'{option}: cannot write into {base} (permission denied)')


def _new_folder(parent: Path, prefix: str) -> Path:
    """A new folder ``prefix`` + 8 random hex digits in ``parent``, with the usual (umask) permissions."""
    while True:
        folder = parent / f'{prefix}{secrets.token_hex(4)}'
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue


def _is_bag_directory(path: Path) -> bool:
    return path.is_dir() and all(e.name in _BAG_FILES or e.suffix == '.mcap' for e in path.iterdir())


class _Target:
    """One folder the run produces: staged beside ``final``, moved into place by commit()."""

    def __init__(self, final: Path, entries: tuple[str, ...] | None):
        self.final = _absolute(final)
        self.entries = entries      #: names owned inside ``final`` (None: ``final`` as a whole)
        self.staging: Path | None = None

    @property
    def staged(self) -> Path:
        """Where the run writes what goes to ``final``."""
        assert self.staging is not None
        return self.staging if self.entries is not None else self.staging / self.final.name

    def create_staging(self, option: str) -> None:
        parent = self.final.parent
        if self.entries is not None and self.final.is_dir() and self.final.stat().st_dev != parent.stat().st_dev:
            parent = self.final      # a mount point: stage on its own file system, so commit can move the entries
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self.staging = _new_folder(parent, self.final.name + STAGING_MARK)
        except OSError as error:
            raise ParameterError(f'{option}: cannot write into {parent}: {error.strerror}') from error

    def commit(self) -> None:
        """Move the staged run into ``final``, replacing what it replaces; the staging folder goes."""
        if self.entries is None:
            replaced = [self.final] if self.final.exists() else []
            produced = [(self.staged, self.final)]
        elif not self.final.exists():
            os.replace(self.staging, self.final)
            self.staging = None
            return
        else:
            replaced = [self.final / name for name in self.entries if (self.final / name).exists()]
            produced = [(entry, self.final / entry.name) for entry in sorted(self.staging.iterdir())]
        trash = _new_folder(self.staging.parent, self.final.name + '.replaced-')
        for old in replaced:
            os.replace(old, trash / old.name)
        for new, final in produced:
            os.replace(new, final)
        shutil.rmtree(trash)
        shutil.rmtree(self.staging)
        self.staging = None

    def discard(self) -> None:
        if self.staging is not None:
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging = None


class RunOutput:
    """Where a run writes: ``out`` (summary, review, plots) and ``bag`` (None: no bag), both staged.

    The constructor only checks (it raises ParameterError naming the option, and touches nothing);
    :meth:`create` makes the staging folders, so an unwritable place fails before any flying.
    """

    def __init__(self, out_dir: Path, bag: Path | None, overwrite: bool):
        self.out_dir, self.bag_path = Path(out_dir), None if bag is None else Path(bag)   #: as given
        self._bag: _Target | None = None
        self._bag_entry: str | None = None      #: name of a bag directly in the output folder
        if self.bag_path is not None and _absolute(self.bag_path).parent == _absolute(self.out_dir):
            self._bag_entry = self.bag_path.name
        entries = RUN_ENTRIES + ((self._bag_entry,) if self._bag_entry not in (None, *RUN_ENTRIES) else ())
        self._out = _Target(self.out_dir, entries)
        self._overwrite = overwrite
        self._lock: FileLock | None = None
        self.leftovers: list[Path] = []      #: earlier unfinished runs' staging folders with content (create())
        self._check_out(overwrite)
        if self.bag_path is not None and self._bag_entry is None:
            self._check_separate_bag(overwrite)
            self._bag = _Target(self.bag_path, None)

    def _check_out(self, overwrite: bool) -> None:
        out = self.out_dir
        if out.exists() and not out.is_dir():
            raise ParameterError(f'--out: {out} exists and is not a folder')
        earlier = [name for name in self._out.entries if (out / name).exists()] if out.is_dir() else []
        if earlier and not overwrite:
            raise ParameterError(f'--out: {out} holds an earlier run ({", ".join(earlier)}); pass '
                                 '--overwrite to replace it, or choose another --out')
        if out.is_dir() and not os.access(out, os.W_OK | os.X_OK):
            raise ParameterError(f'--out: cannot write into {out} (permission denied, or a read-only file system)')
        _check_writable_parent('--out', out)

    def _check_separate_bag(self, overwrite: bool) -> None:
        bag = self.bag_path
        if _absolute(bag) == _absolute(self.out_dir) or _absolute(bag) in _absolute(self.out_dir).parents:
            raise ParameterError(f'--bag: {bag} would hold the output folder {self.out_dir}; choose another --bag')
        if _absolute(self.out_dir) in _absolute(bag).parents:
            raise ParameterError(f'--bag: put the bag directly in the output folder ({self.out_dir / bag.name}) '
                                 'or outside it')
        if bag.exists():
            if not overwrite:
                raise ParameterError(f'--bag: {bag} exists; pass --overwrite to replace it, or choose another --bag')
            if not _is_bag_directory(bag):
                raise ParameterError(f'--bag: {bag} exists and is not a bag (only metadata.yaml and .mcap files); '
                                     'it is not replaced, even with --overwrite')
        _check_writable_parent('--bag', bag)

    def _lock_out(self) -> None:
        """Hold ``out_dir`` for this run (ParameterError naming the other run's process if it is held),
        then check it again: a run that finished meanwhile is an earlier run now."""
        final = self._out.final
        lock = FileLock(final.parent / f'.{final.name}.lock',
                        lambda holder: f'--out: another run is writing {self.out_dir} (process {holder}); let it '
                                       'finish, or choose another --out')
        try:
            final.parent.mkdir(parents=True, exist_ok=True)
            self._lock = lock.acquire()
        except OSError as error:
            raise ParameterError(f'--out: cannot write into {final.parent}: {error.strerror}') from error
        self._check_out(self._overwrite)

    def _unlock(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def create(self) -> None:
        """Lock ``out_dir`` and make the staging folders (raises ParameterError if another run is writing
        it, or it cannot be written); :attr:`leftovers` lists what earlier unfinished runs left."""
        try:
            self._lock_out()
            self.leftovers = self._clear_leftovers()
            self._out.create_staging('--out')
            if self._bag is not None:
                self._bag.create_staging('--bag')
        except ParameterError:
            self.discard()
            raise

    def _clear_leftovers(self) -> list[Path]:
        """The staging folders of earlier runs of ``out_dir`` that did not finish (with the lock held, no
        other run is writing it, so their processes are gone): the empty ones are removed, the others (an
        interrupted flight's bag, say) returned, oldest first."""
        final = self._out.final
        found = sorted((folder for folder in final.parent.glob(f'{final.name}{STAGING_MARK}*') if folder.is_dir()),
                       key=lambda folder: folder.stat().st_mtime)
        kept = []
        for folder in found:
            try:
                folder.rmdir()
            except OSError:
                kept.append(folder)
        return kept

    @property
    def out(self) -> Path:
        """Staged output folder: write the run's files here."""
        return self._out.staged

    @property
    def bag(self) -> Path | None:
        """Staged bag folder (None: no bag)."""
        if self._bag is not None:
            return self._bag.staged
        return None if self._bag_entry is None else self._out.staged / self._bag_entry

    def commit(self) -> None:
        """The run is complete: move it into place (``out_dir``, ``bag_path``)."""
        if self._bag is not None:
            self._bag.commit()
        self._out.commit()
        self._unlock()

    def keep_partial(self) -> list[Path]:
        """The run did not finish: keep what it wrote where it is (staging folders with content), remove
        the empty ones; returns the kept folders."""
        kept = []
        for target in (self._out, self._bag):
            if target is None or target.staging is None:
                continue
            if any(target.staging.iterdir()):
                kept.append(target.staging)
            else:
                target.discard()
        self._unlock()
        return kept

    def discard(self) -> None:
        for target in (self._out, self._bag):
            if target is not None:
                target.discard()
        self._unlock()
