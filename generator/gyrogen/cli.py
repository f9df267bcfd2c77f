"""The `gyrogen` command line's entry point (pyproject's [project.scripts]).

It imports nothing heavy: Ctrl-C is handled first, then the click group and
its commands (commands.group, which imports numpy, scipy and the rest) are
imported behind that handling, so that Ctrl-C at any moment, the imports
included, is one line and exit 130, never a traceback. The command runs in
one files.transaction: after exit 130 every file it wrote is put back (and
every directory it made removed), and once it has ended a Ctrl-C is
ignored, so that "aborted" never stands beside a finished output."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from types import FrameType
from typing import Any

Handler = Callable[[int, FrameType | None], object] | int | None
"""A SIGINT handler as the signal module takes it (a function, SIG_IGN, SIG_DFL)."""

ABORTED = 130
"""The exit code after Ctrl-C (128 + SIGINT, as a shell reports it)."""


class Interrupted(BaseException):
    """Ctrl-C, as main's handler raises it: a BaseException, so that no
    `except Exception` stops it and click does not turn it into its own
    Abort (with a blank line first); `finally` blocks and files'
    roll-backs run as for KeyboardInterrupt."""


_caught: list[int] = []
"""The SIGINTs main's handler took (an import may wrap what it raised: a
class's __set_name__ turns it into a RuntimeError)."""


def _interrupted(signum: int, frame: FrameType | None) -> None:
    _caught.append(signum)
    raise Interrupted


def _unraisable(previous: Callable[[Any], object]) -> Callable[[Any], None]:
    """sys.unraisablehook that is silent on Interrupted: raised where Python
    cannot propagate it (an import lock's weakref callback, a __del__), it is
    lost, not printed; main sees it in _caught and aborts after the command."""

    def hook(unraisable: Any) -> None:
        if not isinstance(getattr(unraisable, "exc_value", None), Interrupted):
            previous(unraisable)

    return hook


def main(argv: list[str] | None = None) -> None:
    """Entry point: one line per error, exit 1 for failures, 2 for usage,
    130 for Ctrl-C. argv None: this call is the process (the console script,
    python -m gyrogen); when it ends, Ctrl-C is ignored (nothing is left to
    stop, and the interpreter's exit prints no traceback). Called with argv
    (tests, in process), it puts the SIGINT handler back as it found it."""
    _caught.clear()
    ended: SystemExit | None = None
    hook = sys.unraisablehook
    sys.unraisablehook = _unraisable(hook)
    previous = _install(_interrupted)  # last before the try: a Ctrl-C from here on is handled
    try:
        from gyrogen.files import transaction  # the standard library's only

        with transaction():  # Ctrl-C: every file the command wrote is put back
            from gyrogen.commands.group import run  # behind the handler: it imports everything

            try:
                run(argv)
            except SystemExit as exc:  # an error's exit code: what was written stays
                ended = exc
            _install(signal.SIG_IGN)  # the command is over: a Ctrl-C now comes too late
            if _caught:  # a Ctrl-C that Python could not raise (see _unraisable)
                raise Interrupted
    except BaseException as exc:
        if isinstance(exc, SystemExit) or not (_caught or _from_ctrl_c(exc)):
            raise
        _install(signal.SIG_IGN)
        sys.stderr.write(("\n" if sys.stderr.isatty() else "") + "gyrogen: aborted\n")
        sys.exit(ABORTED)
    finally:
        if argv is None:
            _install(signal.SIG_IGN)
        elif previous is not None:
            signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = hook
    if ended is not None:
        raise ended


def _from_ctrl_c(exc: BaseException | None) -> bool:
    """exc is Ctrl-C (a KeyboardInterrupt: before main's handler, or from
    click's prompts), or was raised while handling one."""
    while exc is not None:
        if isinstance(exc, (Interrupted, KeyboardInterrupt)):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def _install(handler: Handler) -> Handler:
    """Install handler for SIGINT; the one it replaces. Not where SIGINT is
    ignored (a background job's) or off the main thread (where Python
    installs none), nor where Python installed none itself (None): there
    it is left as it is."""
    try:
        current = signal.getsignal(signal.SIGINT)
        if current is not None and (current is not signal.SIG_IGN or handler is signal.SIG_IGN):
            signal.signal(signal.SIGINT, handler)
        return current
    except ValueError:  # not the main thread
        return None
