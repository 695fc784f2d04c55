"""Folders that the commands fill, replaced as one set and never at a person's expense.

A command (``generate``, ``evaluate``, ``demo``) writes its files into a staging folder inside
its output folder and, once everything is written, moves them in and removes what its previous
run there wrote and this run did not (a stale video, ``sample-3`` after ``--samples 1``). A
record (:data:`MARKER`, JSON) lists every file a command wrote with its SHA-256, so that

* a folder holding files no command wrote, or a written file a person has changed since, is
  refused before any work, unless ``overwrite`` (and even then only files of the same names are
  replaced: nothing else a person put there is removed);
* a full disk or any other error leaves the folder as it was: the staging folder goes, with
  whatever partial file it held, and the message names the file being written.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

#: The record of what a command wrote into a folder: ``{"command": ..., "files": {path: sha256}}``.
MARKER = ".gesturelib-output"
#: How the marker began before it recorded files (version 0.1's folders, taken as written whole).
_OLD_MARKER = "This folder was written by `python -m gesturelib"


class OutputError(Exception):
    """An output folder cannot be used or written; the message says why and what to do."""


def _digest(path: Path) -> str:
    hasher = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            hasher.update(block)
    return hasher.hexdigest()


class OutputFolder:
    """The output folder ``path`` of ``command``, checked on creation (before the work).

    Usage::

        folder = OutputFolder(out, "generate", overwrite)    # refuses here, before any work
        with folder.staging() as stage:                      # files go to stage.path(name)
            np.savez(stage.path("motion.npz"), ...)
        # now in place; the previous run's other files are gone

    Raises:
        OutputError: ``path`` is a file, or holds files no command wrote or that were changed
            since (without ``overwrite``).
    """

    def __init__(self, path: str | os.PathLike, command: str, overwrite: bool = False):
        self.path, self.command, self.overwrite = Path(path), command, overwrite
        if self.path.exists() and not self.path.is_dir():
            raise OutputError(f"{self.path} exists and is not a folder; choose another --out")
        if (self.path / MARKER).exists() and not (self.path / MARKER).is_file():
            raise OutputError(
                f"{self.path / MARKER} is not a file; the commands keep their record of what "
                "they wrote there: rename or remove it"
            )
        self.written = self._record()
        foreign = [] if overwrite else self._foreign()
        if foreign:
            raise OutputError(
                f"{self.path} holds {foreign[0]}"
                + (f" and other files ({len(foreign) - 1}+)" if len(foreign) > 1 else "")
                + f", which `{command}` did not write or which changed since; choose another "
                "--out, or pass --overwrite to replace files of the same names (no others)"
            )

    def _record(self) -> dict[str, str]:
        """The files an earlier command wrote here, by relative path: their SHA-256. A record
        that is damaged, of an older version or names a path outside the folder vouches for
        nothing."""
        marker = self.path / MARKER
        if not marker.is_file():
            return {}
        text = marker.read_text(encoding="utf-8", errors="replace")
        if text.startswith(_OLD_MARKER):  # written before records: its files were all ours
            return {
                p.relative_to(self.path).as_posix(): _digest(p)
                for p in self.path.rglob("*")
                if p.is_file() and p.name != MARKER
            }
        try:
            files = json.loads(text)["files"]
            assert isinstance(files, dict)
        except (ValueError, KeyError, TypeError, AssertionError):
            return {}
        inside = self.path.resolve()
        for name in files:
            if not (self.path / str(name)).resolve().is_relative_to(inside):
                return {}
        return {str(name): str(digest) for name, digest in files.items()}

    def _unchanged(self, name: str) -> bool:
        """Whether the file ``name`` is as this folder's record says a command wrote it."""
        file = self.path / name
        return name in self.written and file.is_file() and _digest(file) == self.written[name]

    def _foreign(self, limit: int = 10) -> list[str]:
        """Up to ``limit`` files here that no command wrote, or that changed since one did."""
        if not self.path.is_dir():
            return []
        found = []
        for file in self.path.rglob("*"):
            if file.is_dir() and not file.is_symlink():
                continue
            name = file.relative_to(self.path).as_posix()
            if name == MARKER or name.startswith(".gesturelib-staging"):
                continue
            if not self._unchanged(name):
                found.append(name)
                if len(found) == limit:
                    break
        return sorted(found)

    def staging(self) -> _Staging:
        """A context whose files move into the folder when it ends without an error."""
        return _Staging(self)

    def _commit(self, stage: Path) -> list[Path]:
        new = {
            p.relative_to(stage).as_posix(): _digest(p)
            for p in sorted(stage.rglob("*"))
            if p.is_file()
        }
        for name in new:  # every check before anything moves
            if (self.path / name).is_dir():
                raise OutputError(
                    f"{self.path / name} is a folder where `{self.command}` writes a file"
                )
        # The previous run's files that this one does not replace, unless a person changed them.
        stale = [name for name in self.written if name not in new and self._unchanged(name)]
        for name in new:
            target = self.path / name
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(stage / name, target)
        record = {"command": self.command, "files": new}
        (self.path / MARKER).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        self.written = new
        for name in stale:
            (self.path / name).unlink(missing_ok=True)
            for parent in (self.path / name).parents:
                if parent == self.path or not parent.is_dir() or any(parent.iterdir()):
                    break
                parent.rmdir()
        return [self.path / name for name in new]


class _Staging:
    """Where a command's files are written before they move into its output folder."""

    def __init__(self, folder: OutputFolder):
        self.folder = folder
        self.current: str | None = None
        self.files: list[Path] = []

    def path(self, name: str) -> Path:
        """Where to write the output file ``name`` (a path relative to the output folder)."""
        self.current = name
        target = self.root / name
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def __enter__(self) -> _Staging:
        out = self.folder.path
        try:
            out.mkdir(parents=True, exist_ok=True)
            self.root = Path(tempfile.mkdtemp(prefix=".gesturelib-staging-", dir=out))
        except OSError as error:
            raise OutputError(f"cannot write into {out}: {error.strerror or error}") from error
        return self

    def __exit__(self, kind, error, traceback) -> bool:
        moving = False
        try:
            if error is None:
                moving = True
                self.files = self.folder._commit(self.root)
        except OSError as failure:
            error = failure
        finally:
            shutil.rmtree(self.root, ignore_errors=True)
        if not isinstance(error, OSError):
            return False
        reason = "the disk is full" if error.errno == errno.ENOSPC else error.strerror or str(error)
        if moving:
            raise OutputError(
                f"cannot move the new files into {self.folder.path}: {reason}; some of them may "
                "have replaced earlier ones"
            ) from error
        raise OutputError(
            f"cannot write {self.current or 'its files'} into {self.folder.path}: {reason}; "
            "nothing there was changed"
        ) from error
