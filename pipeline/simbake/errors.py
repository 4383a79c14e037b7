"""Errors the pipeline reports to users.

Every problem with user input is a :class:`SceneError` whose message is one line naming
the file, the key and what is wrong, e.g. ``scene.toml: bodies[2].mass: must be > 0, got -1``.
The CLI prints it and exits with status 2, without a traceback.
"""

from __future__ import annotations

from pathlib import Path


class SceneError(ValueError):
    """Bad user input: a scene file, a mesh, a cache path."""

    def __init__(self, file: str | Path, key: str, problem: str):
        self.file = str(file)
        self.key = key
        self.problem = problem
        where = f"{self.file}: {key}" if key else self.file
        super().__init__(f"{where}: {problem}")


class SimulationError(RuntimeError):
    """The solver produced a non-finite state; nothing is written."""


class OutputError(OSError):
    """An output could not be written (a full disk, an I/O error); the temp file is removed
    and any earlier file at the output path is left as it was. The CLI exits with status 1."""
