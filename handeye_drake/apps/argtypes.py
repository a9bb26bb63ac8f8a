"""argparse value types shared by the commands: a bad value is a one-line usage error naming the
option (``argument --dpi: expected a positive number, got '0'``), before anything runs."""

from __future__ import annotations

import argparse
import math


def _number(text: str, kind, what: str):
    try:
        return kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def positive_int(text: str) -> int:
    v = _number(text, int, "a positive integer")
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def non_negative_int(text: str) -> int:
    v = _number(text, int, "a non-negative integer")
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}")
    return v


def positive_float(text: str) -> float:
    v = _number(text, float, "a positive number")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def non_negative_float(text: str) -> float:
    v = _number(text, float, "a number ≥ 0")
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"expected a number ≥ 0, got {text!r}")
    return v


def int_up_to(high: int, why: str):
    """An argparse type: a positive integer ≤ ``high`` (a bound on the work an option asks for,
    said in the message with ``why``), e.g. ``int_up_to(100_000, "about 0.5 ms each")``."""
    def parse(text: str) -> int:
        v = positive_int(text)
        if v > high:
            bound = f"{high:_}".replace("_", " ")
            raise argparse.ArgumentTypeError(f"expected at most {bound} ({why}), got {text!r}")
        return v
    parse.__name__ = f"positive integer ≤ {high}"
    return parse


def deg_mm(text: str, positive: bool = True) -> tuple[float, float]:
    """``DEG,MM``: an angle (degrees) and a length (millimetres), the way every command writes
    noise and accuracy (``--max-noise``, ``--robot-accuracy``, ``plan --noise``)."""
    try:
        deg, mm = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected DEG,MM (e.g. 0.1,1), got {text!r}") from None
    ok = (deg > 0 and mm > 0) if positive else (deg >= 0 and mm >= 0)
    if not (ok and math.isfinite(deg) and math.isfinite(mm)):
        raise argparse.ArgumentTypeError(
            f"expected two {'positive numbers' if positive else 'numbers ≥ 0'}, got {text!r}")
    return deg, mm


def positive_deg_mm(text: str) -> tuple[float, float]:
    return deg_mm(text, True)


def non_negative_deg_mm(text: str) -> tuple[float, float]:
    return deg_mm(text, False)
