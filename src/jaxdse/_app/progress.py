"""A one-line progress bar on stderr for long work (plain lines when stderr is not a terminal)."""

from __future__ import annotations

import sys
import time


class Progress:
    """A one-line progress bar on stderr (plain lines when stderr is not a terminal)."""

    def __init__(self, total: int, stream=sys.stderr, width: int = 28):
        self.total, self.done, self.stream, self.width = total, 0, stream, width
        self.t0 = time.perf_counter()
        self.tty = hasattr(stream, "isatty") and stream.isatty()

    def step(self, label: str):
        self.done = min(self.total, self.done + 1)
        frac = self.done / max(self.total, 1)
        bar = "#" * round(frac * self.width) + "-" * (self.width - round(frac * self.width))
        line = f"[{bar}] {self.done}/{self.total} {time.perf_counter() - self.t0:6.1f} s  {label}"
        if self.tty:
            self.stream.write("\r\033[K" + line + ("\n" if self.done == self.total else ""))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def note(self, line: str):
        """A line of its own between steps (the bar, on a terminal, is drawn again at the next)."""
        self.stream.write(("\r\033[K" if self.tty else "") + line + "\n")
        self.stream.flush()
