"""Progress on stderr for commands that run longer than a few seconds (tqdm): a bar redrawn in
place on a terminal, a line every ~10 % in a log file; stdout stays the result."""

from __future__ import annotations

import sys

from tqdm import tqdm


def progress_bar(total: float, description: str, unit: str = "it", enabled: bool = True,
                 stream=None):
    """A tqdm bar on ``stream`` (stderr). Off a terminal it refreshes at most every 10 % or 30 s,
    so a log gets a handful of lines."""
    stream = sys.stderr if stream is None else stream
    tty = bool(getattr(stream, "isatty", lambda: False)())
    return tqdm(total=total, desc=description, unit=unit, file=stream, disable=not enabled,
                dynamic_ncols=tty, mininterval=0.2 if tty else 30.0,
                miniters=None if tty else max(1, int(total // 10)),
                bar_format=None if tty else "{desc}: {n_fmt}/{total_fmt} {unit} "
                "[{elapsed}<{remaining}]", leave=True, ascii=not tty)
