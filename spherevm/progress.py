"""A status line for long runs: redrawn in place on a terminal, one line per update in a log."""
from __future__ import annotations

import sys


class StatusLine:
    """Write progress lines to ``stream`` (standard error by default).

    On a terminal each :meth:`show` overwrites the previous line; elsewhere (a log file, CI) every
    call prints a new line, so callers throttle how often they call it.
    """

    def __init__(self, stream=None):
        self.stream = sys.stderr if stream is None else stream
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.drawn = False

    def show(self, line: str):
        self.stream.write(("\r" + line + "\x1b[K") if self.tty else line + "\n")
        self.stream.flush()
        self.drawn = True

    def close(self):
        """End a line redrawn in place (a no-op in logs)."""
        if self.tty and self.drawn:
            self.stream.write("\n")
            self.stream.flush()
