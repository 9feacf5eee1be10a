"""What the command-line front ends share: argparse types."""
import argparse
import math


def positive_seconds(text: str) -> float:
    """An argparse type: a positive, finite number of seconds (nan, inf, 0 and words refused)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError('%r is not a positive number of seconds' % text)
    return value
