"""Safe outputs: atomic writes, and a user's existing files never replaced by surprise.

Every file or directory the project writes goes through here:

* :func:`atomic_path` / :func:`atomic_open` / :func:`write_text` write a file to a hidden
  temporary sibling (``.NAME.<pid>-<random>.tmp<suffix>``) and rename it onto the target
  only when complete; :func:`atomic_dir` does the same for a directory. A crash, an error
  or Ctrl-C never leaves a half-written output; a full disk raises "no space left for
  'PATH'" naming the user's path (never the temporary one).
* Temporary siblings left by a process that was killed (SIGKILL) are swept the next time
  the same target is written, once their owner process is gone.
* :func:`check_output_file` / :func:`check_output_dir` are the overwrite policy, which the
  CLI runs before any computation: an existing file is replaced only with ``force``; an
  existing non-empty directory only when it holds a previous output of the same command
  (recorded by :func:`atomic_dir` in :data:`OUTPUT_MARKER`, and nothing else added to it)
  or with ``force``. A regular file is never replaced by a directory.
* :func:`open_growing_dir` prepares a directory that a command fills over time, one entry
  at a time (each written atomically): its marker says ``"files": null``, any entry it holds.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from controlmm.errors import ControlMMError

OUTPUT_MARKER = ".controlmm-output.json"
"""File :func:`atomic_dir` writes into every output directory: ``{"kind": ..., "files": [...]}``;
``"files": null`` marks a directory that grows (:func:`open_growing_dir`): any entry is the command's."""

_NO_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_TEMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)-[^.]+\.tmp(\..*)?$")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _parent(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _check_parent(path: Path, make_parents: bool = False) -> None:
    parent = _parent(path)
    if make_parents:  # the first existing ancestor must be a writable directory
        while not parent.exists() and parent != _parent(parent):
            parent = _parent(parent)
    if not parent.exists():
        raise ControlMMError(f"cannot write '{path}': directory '{parent}' does not exist")
    if not parent.is_dir():
        raise ControlMMError(f"cannot write '{path}': '{parent}' is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ControlMMError(f"cannot write '{path}': directory '{parent}' is not writable")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def sweep_stale_temps(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary siblings of ``path`` whose owner process is gone; return them.

    Only names this module creates for ``path`` (``.NAME.<pid>-<random>.tmp...``) are
    considered, and only when process ``pid`` no longer exists.
    """
    path = Path(path)
    parent = _parent(path)
    removed: list[Path] = []
    if not parent.is_dir():
        return removed
    with contextlib.suppress(OSError):
        for entry in parent.iterdir():
            match = _TEMP.match(entry.name)
            if not match or match["name"] != path.name or _alive(int(match["pid"])):
                continue
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                with contextlib.suppress(FileNotFoundError):
                    entry.unlink()
            removed.append(entry)
    return removed


def _temp_prefix(path: Path) -> str:
    return f".{path.name}.{os.getpid()}-"


def _write_error(path: Path, tmp: Path, exc: BaseException) -> ControlMMError | None:
    """The one-line error for a failed write of ``path`` through ``tmp``, naming ``path`` only.

    None when ``exc`` is not about writing (it is then raised as it is).
    """
    if not isinstance(exc, Exception):  # Ctrl-C, SystemExit: not a write error
        return None
    if isinstance(exc, OSError) and exc.errno in _NO_SPACE:
        return ControlMMError(f"no space left for '{path}' ({exc.strerror}); nothing was written")
    if isinstance(exc, OSError) and exc.errno is None and "written" in str(exc):  # numpy's short write
        return ControlMMError(f"no space left for '{path}' (a short write); nothing was written")
    with contextlib.suppress(OSError):
        if shutil.disk_usage(_parent(path)).free < 64 * 1024:
            return ControlMMError(f"no space left for '{path}'; nothing was written")
    if isinstance(exc, OSError) and exc.filename and str(exc.filename).startswith(str(tmp)):
        return ControlMMError(f"cannot write '{path}': {exc.strerror or exc}")
    if isinstance(exc, ControlMMError) and str(tmp) in str(exc):  # a nested write inside ``tmp``
        return ControlMMError(str(exc).replace(str(tmp), str(path)))
    return None


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file keeps the target's suffix so that libraries choosing a format by
    extension (numpy, imageio, matplotlib) behave as for the final name. This is the
    mechanism only: the overwrite policy is :func:`check_output_file`'s.
    """
    path = Path(path)
    _check_parent(path, make_parents=True)
    if path.is_dir():
        raise ControlMMError(f"cannot write '{path}': it is a directory, expected a file")
    try:  # `--out out/walk` in a fresh folder
        _parent(path).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ControlMMError(f"cannot write '{path}': {exc.strerror or exc}") from None
    sweep_stale_temps(path)
    fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=f".tmp{path.suffix}", dir=_parent(path))
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException as exc:
        error = _write_error(path, tmp_path, exc)  # before the clean-up frees the space
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        if error is not None:
            raise error from exc
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """Open a temporary file for writing and rename it onto ``path`` when the block succeeds."""
    if not any(c in mode for c in "wx"):
        raise ValueError(f"atomic_open is for writing; got mode {mode!r}")
    with atomic_path(path) as tmp, open(tmp, mode.replace("x", "w"), **kwargs) as fh:
        yield fh


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Atomically write a text file (UTF-8)."""
    with atomic_open(path, "w", encoding="utf-8") as fh:
        fh.write(text)


def check_output_file(path: str | os.PathLike[str], *, force: bool = False, flag: str = "--force") -> Path:
    """Check that ``path`` can be written as a new file; return it as a Path.

    Missing parent directories are fine (the writers make them: :func:`atomic_path`); raises
    a one-line :class:`ControlMMError` when the nearest existing one is not a directory or is
    read-only, when ``path`` is a directory, or when it exists and ``force`` is false (``flag``
    is named in that message).
    """
    path = Path(path)
    _check_parent(path, make_parents=True)
    if path.is_dir():
        raise ControlMMError(f"'{path}' is a directory; expected a file name to write")
    if path.exists() and not force:
        raise ControlMMError(f"'{path}' exists; pass {flag} to replace it, or choose another name")
    sweep_stale_temps(path)
    return path


def _previous_output(path: Path, kind: str) -> bool:
    """Whether directory ``path`` holds a ``kind`` output written here, and nothing added to it."""
    try:
        marker = json.loads((path / OUTPUT_MARKER).read_text(encoding="utf-8"))
        if marker["kind"] != kind:
            return False
        if marker["files"] is None:  # a growing directory (open_growing_dir): every entry is the command's
            return True
        files = set(marker["files"]) | {OUTPUT_MARKER}
        return all(p.name in files for p in path.iterdir())
    except (OSError, ValueError, KeyError, TypeError):
        return False


def check_output_dir(
    path: str | os.PathLike[str],
    *,
    kind: str | None,
    force: bool = False,
    flag: str = "--force",
    make_parents: bool = False,
) -> Path:
    """Check that directory ``path`` can be (re)written by a ``kind`` command; return it.

    Allowed: a new name, an empty directory, a previous ``kind`` output (see
    :data:`OUTPUT_MARKER`; ``kind=None`` never matches), or any directory with ``force``.
    Never allowed: a regular file. Stale temporaries of killed runs are swept. With
    ``make_parents`` missing parent directories are allowed (:func:`atomic_dir` creates them).
    """
    path = Path(path)
    _check_parent(path, make_parents)
    if path.exists() and not path.is_dir():
        raise ControlMMError(f"'{path}' is a file, not a directory; choose another output directory")
    if path.is_dir() and not force and any(path.iterdir()):
        if kind is None or not _previous_output(path, kind):
            what = f"a previous '{kind}' output" if kind else "an output of this command"
            raise ControlMMError(
                f"'{path}' is not empty and does not hold {what}; pass {flag} to replace it, "
                "or choose another output directory"
            )
    sweep_stale_temps(path)
    return path


@contextlib.contextmanager
def atomic_dir(
    path: str | os.PathLike[str],
    *,
    kind: str | None,
    force: bool = False,
    flag: str = "--force",
    make_parents: bool = False,
) -> Iterator[Path]:
    """Yield a temporary directory beside ``path``; on success it replaces ``path``.

    ``path`` must pass :func:`check_output_dir` (checked again here). The finished directory
    records its ``kind`` and file names in :data:`OUTPUT_MARKER`, so that the next run of
    the same command may replace it without ``force``. An existing directory is replaced
    only once the new one is complete. ``make_parents`` creates missing parent directories.
    """
    path = check_output_dir(path, kind=kind, force=force, flag=flag, make_parents=make_parents)
    _parent(path).mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=_parent(path)))
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        yield tmp
        if kind is not None:
            files = sorted(p.name for p in tmp.iterdir())
            (tmp / OUTPUT_MARKER).write_text(json.dumps({"kind": kind, "files": files}) + "\n")
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=_parent(path)))
            os.replace(path, old / path.name)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException as exc:
        error = _write_error(path, tmp, exc)  # before the clean-up frees the space
        shutil.rmtree(tmp, ignore_errors=True)
        if error is not None:
            raise error from exc
        raise


def open_growing_dir(
    path: str | os.PathLike[str],
    *,
    kind: str,
    force: bool = False,
    flag: str = "--force",
    make_parents: bool = False,
) -> Path:
    """Prepare directory ``path`` for a ``kind`` command that fills it over time; return it.

    For outputs written entry by entry (each entry atomically, e.g. with :func:`atomic_dir`)
    rather than in one piece. ``path`` must pass :func:`check_output_dir`: without ``force`` a
    previous ``kind`` output is kept as it is (the command resumes it); with ``force`` whatever
    a non-empty ``path`` holds (a previous ``kind`` output too) is moved aside and deleted, and
    the command starts over in an empty directory. The directory is marked with
    ``{"kind": kind, "files": null}`` in :data:`OUTPUT_MARKER`.
    """
    path = check_output_dir(path, kind=kind, force=force, flag=flag, make_parents=make_parents)
    if force and path.is_dir() and any(path.iterdir()):
        old = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=_parent(path)))
        os.replace(path, old / path.name)
        shutil.rmtree(old, ignore_errors=True)
    path.mkdir(parents=True, exist_ok=True)
    marker = path / OUTPUT_MARKER
    if not _previous_output(path, kind):
        write_text(marker, json.dumps({"kind": kind, "files": None}) + "\n")
    return path
