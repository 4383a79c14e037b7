"""The memory estimate holds (issue 30, item 8): a cloth bake's measured peak is within 10% of
its estimate.

Issue 30's repro was a 500 x 500 cloth estimated 1.95 GiB that peaked at 2.35 GB, and 1000 x
1000 estimated 7.63 GiB past 8.5 GiB (8 kB a vertex and nothing else). Those take minutes and
gigabytes; the same model is checked here where it is cheap: a 160 x 160 sheet pinned at its
four corners, 13 frames, so that its self-collision pairs have appeared (the old estimate
said 200 MiB, half its peak). The peak is the bake's own process's peak resident set
(VmHWM: not ru_maxrss, which counts the test runner's resident set at the fork), in a fresh interpreter, on one thread, as benchmarks/memory/cloth_peak.py
measures it for the table in benchmarks/results/memory_estimate.md.
"""

from __future__ import annotations

import json
import subprocess
import sys

from benchmarks.memory.cloth_peak import RUN

SCENE = """[scene]
end_frame = 13
[solver]
substeps = 1
[[cloths]]
name = "sheet"
grid = { size = [2.0, 2.0], resolution = [160, 160] }
position = [0.0, 1.0, 0.0]
pinned = [0, 159, 25440, 25599]
"""


def test_a_cloth_bakes_within_its_memory_estimate(tmp_path):
    (tmp_path / "sheet.toml").write_text(SCENE)
    result = subprocess.run([sys.executable, "-c", RUN, str(tmp_path / "sheet.toml"), str(tmp_path / "sheet.usdc")],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    measured = json.loads(result.stdout.strip().splitlines()[-1])
    ratio = measured["peak"] / measured["estimate"]
    # never more than 10% over it (the estimate is what a user plans for), nor far under it:
    # the same bake's peak measured 0.94-1.01 of it alone and 0.885-0.90 beside other tests in
    # the suite (the cause not found: the bake is the same)
    assert 0.8 <= ratio <= 1.1, (measured["peak"] / 2**20, measured["estimate"] / 2**20)
