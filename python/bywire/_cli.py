"""The ``bywire`` command, installed with the package: the command line itself, run by the
native module (the same code as the ``bywire`` binary cargo builds)."""

from __future__ import annotations

import signal
import sys

from . import _native


def main() -> None:
    # The command line's own signal handling, as in its binary: Ctrl-C ends a command that
    # does not catch it (Python's handler would only set a flag nobody reads).
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    sys.stdout.flush()
    sys.exit(_native.run_cli(sys.argv))


if __name__ == "__main__":
    main()
