"""simbake's benchmarks, importable as the package `benchmarks` wherever the checkout's root is
on the path: pytest (pyproject's `pythonpath`) and the environment `make install` builds.

Scripts are still run as files (`.venv/bin/python benchmarks/rigid/piles.py`). A module
shared across folders is imported by its package path (`from benchmarks import common`,
`from benchmarks.peers import scenes`), never through an edit of `sys.path`. The modules a
peer engine's runner loads in that engine's own Python (peers/scenes.py, cloth/drape_spec.py,
cloth/crossings.py) import only the standard library, NumPy and each other.
"""
