"""Writing files so that they appear whole or not at all, and never over an input.

Every file simbake writes (USD caches, QA sidecars, .vdb level sets, cache entries,
previews, reports) goes through here:

* :func:`check_output_path` runs before any work: the suffix, the directory (it must exist
  and take a new file: a probe is created and removed, so a read-only file system, ``/proc``
  or a directory without write permission is refused up front), and the rule that no output
  may be any file the command reads (compared by the file's identity, so a symlink, a hard
  link or another spelling of the same path is caught).
* :func:`write_atomically` (and :func:`commit` for writers that manage their own temp file,
  the USD cache) writes beside the target under a hidden temp name
  ``.NAME.<pid>-<token>.tmp<suffix>``, flushes it to disk (``fsync``: a full disk shows here
  at the latest), optionally checks it (``verify``), and renames it into place; on any error
  the temp file is removed, the old file is left as it was, and the error is an
  :class:`~simbake.errors.OutputError` with one line naming the file.
* :func:`remove_stale_temps` removes temp files that a killed process (SIGKILL, a power cut)
  left beside an output, judged by their pid: it runs whenever the same output is written
  again. A temp whose pid is alive on this machine is left alone.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import secrets
import shutil
import stat
from pathlib import Path
from typing import Callable, Collection, Iterable

from .errors import OutputError, SceneError

# a temp file or folder (".tmp", ".tmp.usdc"), or an earlier output moved aside while a
# bake's outputs were being swapped in (".old")
_TEMP = re.compile(r"\.(?P<name>.+)\.(?P<pid>\d+)-[0-9A-Za-z-]+\.(?:tmp(\.[0-9A-Za-z]+)?|(?P<old>old))")


def temp_path(path: Path, suffix: str | None = None) -> Path:
    """A fresh hidden temp name beside `path`: ``.NAME.<pid>-<token>.tmp<suffix>``."""
    path = Path(path)
    suffix = path.suffix if suffix is None else suffix
    return path.parent / f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}"


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # another user's process (or a pid we cannot ask about): leave it
    return True


def is_temp(name: str) -> bool:
    """Whether a file or folder name is one of temp_path's temps, or an earlier output moved
    aside while a bake's outputs were swapped in."""
    return _TEMP.fullmatch(name) is not None


def is_stale_temp(name: str, of: Collection[str]) -> bool:
    """Whether a file or folder name is a temp of an output named in `of` (a name, not a path)
    left by a process that is gone."""
    match = _TEMP.fullmatch(name)
    return bool(match) and match["name"] in of and not _alive(int(match["pid"]))


def remove_stale_temps(path: Path) -> list[Path]:
    """Remove temps of `path` (files or folders) left by processes that are gone; returns what
    was removed. An earlier output that a killed bake had moved aside (``.old``) is put back
    when nothing took its place, else removed."""
    path = Path(path)
    removed = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return removed
    for entry in entries:
        match = _TEMP.fullmatch(entry.name)
        if not match or match["name"] != path.name or _alive(int(match["pid"])):
            continue
        try:
            if match["old"] and not os.path.lexists(path):
                os.rename(entry.path, path)
                continue
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.remove(entry.path)
            removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


def sha256_of(path: Path) -> str:
    """The SHA-256 (hex) of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def remove_if_present(path: Path) -> None:
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


def fsync_path(path: Path, directory: bool = False) -> None:
    """Flush a file (or a folder's entries) to disk; folders that cannot be flushed pass."""
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    except OSError as error:
        if not directory or error.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise
    finally:
        os.close(fd)


def describe(error: BaseException) -> str:
    """An OSError (or a library's error) as a short phrase: 'No space left on device'."""
    if isinstance(error, OSError) and error.strerror:
        return error.strerror
    text = str(error).strip().splitlines()
    if not text:
        return type(error).__name__
    # USD's errors: "Error in 'Func' at line N in file F : 'the message'" -> the message
    return text[0].rsplit(" : '", 1)[-1].rstrip("'") if " : '" in text[0] else text[0]


def commit(tmp: Path, path: Path) -> None:
    """Flush the finished temp file to disk and rename it onto `path` (atomic, same
    directory); the file gets the permissions of any new file (0666 less the umask)."""
    fsync_path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, path)
    fsync_path(path.parent, directory=True)


def write_atomically(path: Path, write: Callable[[str], None],
                     verify: Callable[[str], None] | None = None) -> None:
    """Call write(tmp) on a temporary path beside `path`, check it, then rename it into place.

    `verify(tmp)` (optional) raises when the written file is not what was meant (for writers
    that do not report their own I/O errors). On failure the temporary file is removed,
    `path` is untouched, and an OSError becomes an :class:`OutputError` naming `path`.
    """
    path = Path(path)
    remove_stale_temps(path)
    tmp = temp_path(path)
    try:
        write(str(tmp))
        if verify is not None:
            fsync_path(tmp)
            verify(str(tmp))
        commit(tmp, path)
    except OSError as error:
        raise OutputError(f"{path}: cannot write: {describe(error)}; nothing was replaced") from None
    finally:
        if tmp.exists():
            tmp.unlink()


def check_input_file(path: Path, file: str | Path, key: str) -> None:
    """A file to read must be a readable regular file; else a one-line SceneError that says
    why (missing, a symlink loop, a directory, permission)."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise SceneError(file, key, f"no such file: {path}") from None
    except (OSError, ValueError) as error:
        raise SceneError(file, key, f"cannot read {path}: {describe(error)}") from None
    if stat.S_ISDIR(info.st_mode):
        raise SceneError(file, key, f"{path} is a directory, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise SceneError(file, key, f"{path} is not a regular file")
    if not os.access(path, os.R_OK):
        raise SceneError(file, key, f"cannot read {path}: permission denied")


def _resolved(path: Path) -> str:
    """The path as the OS would walk it: absolute, '..' and symlinks resolved."""
    return os.path.realpath(os.path.abspath(path))


def _identity(path: Path):
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return None
    return info.st_dev, info.st_ino


def same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file: by identity when both exist (a hard link, a symlink),
    else by normalised, resolved path (``sub/../c.usdc``)."""
    ia, ib = _identity(a), _identity(b)
    if ia is not None and ib is not None:
        return ia == ib
    return _resolved(a) == _resolved(b)


def inside(path: Path, folder: Path) -> bool:
    """Whether `path` lies within `folder`: by resolved path, or one of its resolved parents
    is `folder` itself (by identity)."""
    resolved, top = _resolved(path), _resolved(folder)
    if resolved != top and os.path.commonpath([resolved, top]) == top:
        return True
    target = _identity(folder)
    return target is not None and any(_identity(parent) == target for parent in Path(resolved).parents)


def check_output_name(path: Path) -> None:
    """A name USD and every shell can hold: no newline or other control character."""
    if any(not c.isprintable() for c in str(path)):
        shown = "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in str(path))
        raise SceneError(shown, "", "an output name with a newline or another control character; give "
                                    "another output name")


def check_output_path(path: Path, suffixes: tuple[str, ...], inputs: Iterable[Path] = ()) -> None:
    """Reject an output path before any work is done: wrong suffix, missing or unwritable
    directory, a directory, or any of `inputs` (the files the command reads)."""
    path = Path(path)
    check_output_name(path)
    if path.suffix.lower() not in suffixes:
        raise SceneError(path, "", f"output must end in {', '.join(suffixes)}")
    try:
        parent_is_dir = path.parent.is_dir()
        is_dir = path.is_dir()
    except OSError as error:  # a symlink loop, a name too long
        raise SceneError(path, "", f"cannot use as output: {describe(error)}") from None
    if not parent_is_dir:
        raise SceneError(path, "", f"directory {path.parent} does not exist")
    if is_dir:
        raise SceneError(path, "", "is a directory; give a file name")
    for source in inputs:
        if source is not None and same_file(path, Path(source)):
            raise SceneError(path, "", f"would write over the input {source}; give another output (-o)")
    probe = temp_path(path, ".probe")
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as error:
        raise SceneError(path, "", f"cannot write in {path.parent}: {describe(error)}") from None
    remove_if_present(probe)
