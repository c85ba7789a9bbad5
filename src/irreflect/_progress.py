"""Progress display for long runs: a tqdm bar on a terminal, plain lines elsewhere.

Through a pipe or into a log file a tqdm bar is a flood of carriage returns; there
:func:`progress` prints one line per stage instead (``reproduce: [3/25] selection:
terrazzo``) and, for a long count without stages, a line at every quarter.
"""

from __future__ import annotations

import sys
import time

from tqdm import tqdm


def on_terminal(stream=None) -> bool:
    """True when ``stream`` (default stderr) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class _Lines:
    """The non-terminal display: one line per stage (``set_description`` /
    ``set_postfix_str`` with a new message and ``update``), a line per quarter of a
    count without messages, and a final line on ``close``."""

    def __init__(self, total=None, desc="", unit="it", stream=None, **_ignored):
        self.total = total
        self.n = 0
        self.desc = desc
        self.unit = unit
        self.stream = sys.stderr if stream is None else stream
        self._message = ""
        self._status = ""
        self._printed_message = ""
        self._quarter = 0
        self._t0 = time.perf_counter()
        self._closed = False

    def _line(self, text: str) -> None:
        print(text, file=self.stream, flush=True)

    def _where(self) -> str:
        return f"[{self.n}/{self.total}] " if self.total else ""

    def set_postfix_str(self, message="", refresh=True) -> None:
        # refresh=True: a new stage (one line); refresh=False: a status shown only with
        # the quarter lines of a count (e.g. the best score so far)
        if refresh:
            self._message = str(message)
        else:
            self._status = str(message)

    def set_description(self, desc="", refresh=True) -> None:
        self.desc = str(desc)

    def refresh(self) -> None:
        self._report()

    def update(self, n=1) -> None:
        self.n += n
        self._report()

    def _report(self) -> None:
        if self._message and self._message != self._printed_message:
            self._printed_message = self._message
            self._line(f"{self.desc}: {self._where()}{self._message}")
        elif not self._message and self.total:
            quarter = int(4 * self.n / max(self.total, 1))
            if quarter > self._quarter and self.n < self.total:
                self._quarter = quarter
                status = f" ({self._status})" if self._status else ""
                self._line(f"{self.desc}: {self.n}/{self.total} {self.unit}{status}")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self.n:
            done = f"{self.n}/{self.total}" if self.total else f"{self.n}"
            self._line(f"{self.desc}: done ({done} {self.unit}, "
                       f"{time.perf_counter() - self._t0:.1f} s)")

    def __iter__(self):  # pragma: no cover - not used as an iterator
        raise TypeError("use progress(...) with update()")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Silent:
    n = 0
    total = None

    def __getattr__(self, name):
        return lambda *a, **k: None


def progress(total=None, desc: str = "", unit: str = "it", *, enabled: bool = True,
             stream=None, leave: bool = True):
    """A progress display with tqdm's ``update``, ``set_postfix_str``, ``refresh``,
    ``close``: a tqdm bar when ``stream`` (stderr) is a terminal, plain lines otherwise,
    nothing when not ``enabled``."""
    if not enabled:
        return _Silent()
    stream = sys.stderr if stream is None else stream
    if on_terminal(stream):

        return tqdm(total=total, desc=desc, unit=unit, file=stream, dynamic_ncols=True,
                    leave=leave)
    return _Lines(total=total, desc=desc, unit=unit, stream=stream)
