"""Numbers for JSON output: JSON has no NaN or infinity, so a figure the data could not
determine (NaN, its reason given beside it) is written as null, never as a made-up number."""

from __future__ import annotations

import math

import numpy as np


def finite_or_none(value):
    """``value`` with every NaN or infinite float, inside dicts, lists and tuples too, made None;
    numpy floats become Python floats, anything else is left as it is."""
    if isinstance(value, (float, np.floating)):
        number = float(value)
        return number if math.isfinite(number) else None
    if isinstance(value, dict):
        return {key: finite_or_none(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(item) for item in value]
    return value
