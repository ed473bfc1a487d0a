"""The operator of a stage without a motor: what a sweep or a calibration asks them before a
cycle at a new orientation. Imports nothing else of the sweep, so that a supervisor relaying
the operator's answers (``mows-graph``) starts without the fit."""

import math


def turn_prompt(theta0_rad: float) -> str:
    """What the operator of a stage without a motor is asked before a cycle at ``theta0_rad``."""
    return f"turn the probe to θ0 = {math.degrees(theta0_rad):g}° and confirm"
