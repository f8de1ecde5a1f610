"""Command-line values checked where they are parsed: each an ``argparse`` type that
refuses a value outside its range with one sentence naming the value and the range
(argparse then prints the command's usage and exits 2)."""

from __future__ import annotations

import argparse
import math

__all__ = ["count", "index", "positive_number"]


def positive_number(text: str) -> float:
    """A finite number above 0 (a scale, a length, a time)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"'{text}' must be a finite number above 0.")
    return value


def _whole(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = low - 1
    if value < low:
        raise argparse.ArgumentTypeError(f"'{text}' must be a whole number {what}.")
    return value


def count(text: str) -> int:
    """A whole number of at least 1 (how many frames, people, seconds...)."""
    return _whole(text, 1, "of at least 1")


def index(text: str) -> int:
    """A position counted from 0."""
    return _whole(text, 0, "counted from 0 (0 is the first)")
