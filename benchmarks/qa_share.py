"""The QA's share of a bake: `simbake bake SCENE` in this process with --threads 1, and the
main thread's CPU time spent recording the QA figures (QualityRecorder.record, every frame)
and writing the sidecar (QualityRecorder.write), against the whole.

    .venv/bin/python benchmarks/qa_share.py SCENE OUT.usdc [more simbake bake options]

Thread CPU time, not wall: the machine is shared, and with one solver thread the main
thread does all of a bake's work.
"""

from __future__ import annotations

import sys
import time

START = time.thread_time()

from simbake import cli, qa  # noqa: E402  (timed from before the import)

SPENT = {"record": 0.0, "write": 0.0}


def _timed(name, method):
    def timed(*args, **kwargs):
        start = time.thread_time()
        try:
            return method(*args, **kwargs)
        finally:
            SPENT[name] += time.thread_time() - start
    return timed


def main() -> int:
    if len(sys.argv) < 3:
        print(__doc__)
        return 2
    qa.QualityRecorder.record = _timed("record", qa.QualityRecorder.record)
    qa.QualityRecorder.write = _timed("write", qa.QualityRecorder.write)
    status = cli.main(["bake", sys.argv[1], "-o", sys.argv[2], "-q", "--threads", "1"] + sys.argv[3:])
    total = time.thread_time() - START
    share = SPENT["record"] + SPENT["write"]
    print(f"{sys.argv[1]}: main thread {total:.3f} s CPU, QA {share:.3f} s ({100 * share / total:.1f}%: "
          f"figures {SPENT['record']:.3f} s, sidecar {SPENT['write']:.3f} s)")
    return status


if __name__ == "__main__":
    sys.exit(main())
