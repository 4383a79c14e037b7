"""Writing files so that they appear only when complete."""

from __future__ import annotations

import os
import secrets
from pathlib import Path
from typing import Callable


def write_atomically(path: Path, write: Callable[[str], None]) -> None:
    """Call write(tmp) on a temporary path beside `path`, then rename it into place.

    The file gets the permissions of any new file (0666 less the umask); on failure the
    temporary file is removed and `path` is untouched.
    """
    tmp = path.parent / f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}"
    try:
        write(str(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def check_output_path(path: Path, suffixes: tuple[str, ...]) -> None:
    """Reject an output path before any work is done: wrong suffix, missing directory, a directory."""
    from .errors import SceneError

    if path.suffix.lower() not in suffixes:
        raise SceneError(path, "", f"output must end in {', '.join(suffixes)}")
    if not path.parent.is_dir():
        raise SceneError(path, "", f"directory {path.parent} does not exist")
    if path.is_dir():
        raise SceneError(path, "", "is a directory; give a file name")
