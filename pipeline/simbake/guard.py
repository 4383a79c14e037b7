"""How a simbake command ends: one line on stderr and a documented exit status, never a
traceback (README, "Guarantees").

    0    done
    1    the bake failed (non-finite state), an output could not be written (full disk, I/O
         error), a check found problems, or an internal error (SIMBAKE_DEBUG=1 shows its
         traceback)
    2    bad input: a scene, mesh, cache or output path (the message names file and key)
    128+n  ended by signal n: Ctrl-C (SIGINT, 130), SIGTERM (143), SIGHUP (129); the output
         being written is discarded (its temp file removed), earlier files are untouched
    141  stdout was closed (a broken pipe, `simbake ... | head -c1`): what was being written
         to disk is complete, the rest of the printed text is lost

SIGTERM and SIGHUP are turned into an exception in the main thread, as Ctrl-C is, so every
``with`` block and ``finally`` on the way out removes its temp file. A signal that arrives
while the core steps a frame (the GIL released) takes effect within 50 ms and one substep:
``World.step_frame`` lets the handlers run between substeps and raises what they raise.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import warnings
from typing import Callable

from .errors import OutputError

HANDLED_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class Terminated(BaseException):
    """Raised in the main thread when SIGTERM or SIGHUP arrives (like KeyboardInterrupt)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _on_signal(signum, frame) -> None:
    for s in HANDLED_SIGNALS:  # a second signal must not interrupt the cleanup of the first
        signal.signal(s, signal.SIG_IGN)
    raise Terminated(signum)


def quiet_libraries() -> None:
    """The command line prints its own messages only: trimesh's log lines would come before
    the one error line (NumPy's warnings are ignored while a command runs, see run)."""
    logger = logging.getLogger("trimesh")
    if not any(isinstance(h, logging.NullHandler) for h in logger.handlers):
        logger.addHandler(logging.NullHandler())
    logger.propagate = False


def _print_error(text: str) -> None:
    try:
        print(f"simbake: error: {text}", file=sys.stderr)
    except (OSError, ValueError):
        pass  # stderr itself is gone: the exit status is all that is left


def run(command: Callable[[], int]) -> int:
    """Run a CLI command; turn signals, output failures, a broken pipe and unexpected errors
    into one line and an exit status."""
    quiet_libraries()
    previous = {}
    for s in HANDLED_SIGNALS:
        try:
            previous[s] = signal.signal(s, _on_signal)
        except ValueError:  # not the main thread: leave the signals alone
            pass
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # NumPy's and trimesh's RuntimeWarnings
            return command()
    except Terminated as stop:
        try:
            print(f"simbake: {signal.Signals(stop.signum).name}: stopped; nothing more was written",
                  file=sys.stderr)
        except (OSError, ValueError):
            pass
        return 128 + stop.signum
    except OutputError as error:
        _print_error(str(error))
        return 1
    except BrokenPipeError:
        # stdout was closed by its reader: send the rest nowhere, so the interpreter's own
        # flush at exit does not print a traceback
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 128 + signal.SIGPIPE
    except MemoryError:
        _print_error("out of memory (see README, \"Resource budget\")")
        return 1
    except Exception as error:  # a bug: still one line, the traceback on request
        if os.environ.get("SIMBAKE_DEBUG"):
            raise
        first = (str(error).strip().splitlines() or [""])[0]
        _print_error(f"internal error: {type(error).__name__}: {first} "
                     "(SIMBAKE_DEBUG=1 shows the traceback; please report it)")
        return 1
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
