"""A bake's outputs as one commit: checked against every input before any work, staged
beside their targets, then swapped in together (README, "Guarantees").

A bake writes up to five things: the cache (``OUT.usdc``), its value clips (``OUT.clips/``),
the level sets it used (``OUT.vdb/``), a ``--shot`` stage and the QA sidecar
(``OUT.qa.json``).

* :func:`check_outputs` runs before any work. Every output file and every folder an output
  replaces is compared with every input (the scene file, a shot's layers and every asset
  they name, meshes) and with every other output: by the file's identity (a hard link, a
  symlink) and by its normalised, resolved path (``sub/../c.usdc``), and an input inside a
  folder that would be replaced counts too. A folder at ``OUT.clips`` or ``OUT.vdb`` is
  replaced only when it is a folder that holds nothing but what a bake writes there; a user's
  file of that name, a symlink, or a folder with anything else in it is refused, never
  renamed away. Temps that a killed bake left beside any of the outputs are removed here.
* :class:`Outputs` holds the staged outputs: each is written whole under a hidden temp name
  beside its target (``.NAME.<pid>-<token>.tmp``) and flushed to disk. :meth:`Outputs.commit`
  then moves every earlier output aside (``.NAME.<pid>-<token>.old``), renames each temp into
  place, and removes the earlier ones only when all are in; if any rename fails, what was
  placed is moved back and every earlier output is restored as it was. SIGINT, SIGTERM and
  SIGHUP are held during the commit (a few renames) and act when it ends. On any failure
  before the commit nothing at the targets has changed.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import stat
from pathlib import Path
from typing import Callable, Iterable

from .errors import OutputError, SceneError
from .files import describe, fsync_path, inside, remove_stale_temps, same_file, temp_path

# what a bake writes into its folders: anything else there is the user's
FOLDER_CONTENTS = {
    ".clips": re.compile(r"clip\.\d+\.usd[ac]?|topology\.usd[ac]?|manifest(\.[A-Za-z0-9_]+)?\.usda"),
    ".vdb": re.compile(r"[^/]+\.vdb"),
}
_HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}


# --------------------------------------------------------------------------------------------
# before any work
# --------------------------------------------------------------------------------------------

def _check_folder(folder: Path) -> None:
    """A folder a bake replaces: absent, or a real folder of nothing but what a bake writes."""
    try:
        info = os.lstat(folder)
    except FileNotFoundError:
        return
    except OSError as error:
        raise SceneError(folder, "", f"cannot use as an output folder: {describe(error)}") from None
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        kind = "a symlink" if stat.S_ISLNK(info.st_mode) else "a file"
        raise SceneError(folder, "", f"is {kind}, not a folder simbake wrote; the bake would replace it: "
                                     "move it away or give another output (-o)")
    pattern = FOLDER_CONTENTS[folder.suffix]
    foreign = sorted(e.name for e in os.scandir(folder) if not (e.is_file(follow_symlinks=False)
                                                                and pattern.fullmatch(e.name)))
    if foreign:
        raise SceneError(folder, "", f"holds {foreign[0]!r}, which simbake did not write there; the bake would "
                                     "replace the folder: move it away or give another output (-o)")


def check_outputs(files: Iterable[Path], folders: Iterable[Path], inputs: Iterable[Path]) -> None:
    """Refuse outputs that would write over, replace or delete an input or each other.

    `files`: output files (the cache, a --shot stage, the sidecar); `folders`: folders the bake
    replaces (OUT.clips, OUT.vdb); `inputs`: every file the bake reads. Stale temps of killed
    bakes beside each output are removed.
    """
    files, folders = [Path(p) for p in files], [Path(p) for p in folders]
    inputs = [Path(p) for p in inputs if p is not None]
    outputs = files + folders
    for k, out in enumerate(outputs):
        for source in inputs:
            if same_file(out, source):
                raise SceneError(out, "", f"would write over the input {source}; give another output (-o)")
            if out in folders and inside(source, out):
                raise SceneError(out, "", f"the bake replaces this folder, which holds the input {source}; "
                                          "give another output (-o)")
        for other in outputs[k + 1:]:
            if same_file(out, other) or (other in folders and inside(out, other)) \
                    or (out in folders and inside(other, out)):
                raise SceneError(other, "", f"must differ from the output {out} (it is the same file, or inside "
                                            "the other's folder); give outputs that differ")
    for folder in folders:
        _check_folder(folder)
    for out in outputs:
        remove_stale_temps(out)


# --------------------------------------------------------------------------------------------
# staged, then committed together
# --------------------------------------------------------------------------------------------

def _remove(path: Path) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            os.remove(path)
    except FileNotFoundError:
        pass


def _fsync_tree(path: Path) -> None:
    """A staged file, or a staged folder's files and the folder itself, flushed to disk."""
    if path.is_dir():
        for entry in os.scandir(path):
            if entry.is_file(follow_symlinks=False):
                fsync_path(Path(entry.path))
        fsync_path(path, directory=True)
    else:
        fsync_path(path)


def _permissions(path: Path) -> None:
    """Those of any new file or folder (0666 / 0777 less the umask)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, (0o777 if path.is_dir() else 0o666) & ~umask)


class Outputs:
    """The outputs of one bake, staged beside their targets and committed together.

    Used as a context manager: leaving the block without :meth:`commit` (an error, a signal)
    removes every temp. ``temp(final)``, ``temp_dir(final)`` name temps beside a target;
    ``stage(tmp, final)`` marks a finished temp for the commit; ``write(final, fn)`` writes
    one with fn(tmp) and stages it.
    """

    def __init__(self):
        self._temps: list[Path] = []
        self._staged: dict[Path, Path] = {}  # final -> temp, in the order staged

    def __enter__(self) -> "Outputs":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.abort()

    def temp(self, final: Path, suffix: str | None = None) -> Path:
        tmp = temp_path(Path(final), suffix)
        self._temps.append(tmp)
        return tmp

    def temp_dir(self, final: Path) -> Path:
        tmp = self.temp(final, "")
        tmp.mkdir()
        return tmp

    def staged(self, final: Path) -> Path | None:
        """The finished temp that will become `final`, or None."""
        return self._staged.get(Path(final))

    def stage(self, tmp: Path, final: Path) -> None:
        """`tmp` is finished: flushed now, renamed onto `final` at the commit."""
        tmp, final = Path(tmp), Path(final)
        if tmp not in self._temps:
            self._temps.append(tmp)
        try:
            _fsync_tree(tmp)
            _permissions(tmp)
        except OSError as error:
            raise OutputError(f"{final}: cannot write: {describe(error)}; nothing was replaced") from None
        self._staged[final] = tmp

    def write(self, final: Path, write: Callable[[str], None]) -> None:
        """write(tmp) beside `final`, then stage it; an OSError is an OutputError naming it."""
        tmp = self.temp(final)
        try:
            write(str(tmp))
        except OSError as error:
            raise OutputError(f"{final}: cannot write: {describe(error)}; nothing was replaced") from None
        self.stage(tmp, final)

    def commit(self) -> None:
        """Every staged output into place, or none (see the module docstring)."""
        held = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD_SIGNALS)
        try:
            self._swap_in()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)

    def _swap_in(self) -> None:
        placed: list[tuple[Path, Path, Path | None]] = []  # (final, tmp, the earlier output moved aside)
        try:
            for final, tmp in self._staged.items():
                earlier = None
                if os.path.lexists(final):
                    earlier = temp_path(final, "").with_suffix(".old")
                    os.rename(final, earlier)
                placed.append((final, tmp, earlier))
                os.rename(tmp, final)
            for directory in {final.parent for final in self._staged}:
                fsync_path(directory, directory=True)
        except BaseException as error:
            self._roll_back(placed)
            if isinstance(error, OSError):
                raise OutputError(f"{placed[-1][0] if placed else 'output'}: cannot write: {describe(error)}; "
                                  "nothing was replaced") from None
            raise
        for _, _, earlier in placed:
            if earlier is not None:
                _remove(earlier)
        self._staged.clear()
        self._temps.clear()

    @staticmethod
    def _roll_back(placed) -> None:
        for final, tmp, earlier in reversed(placed):
            if not os.path.lexists(tmp) and os.path.lexists(final):
                os.rename(final, tmp)
            if earlier is not None:
                os.rename(earlier, final)

    def abort(self) -> None:
        """Remove every temp (the targets were never touched)."""
        for tmp in self._temps:
            _remove(tmp)
        self._temps.clear()
        self._staged.clear()
