"""Which way each wiring of a probe calibration is connected, from the ring-downs themselves.

A pair connected the other way round turns the applied field's sign: the measured frequencies
then move against the model's frequency shifts. Within each orientation (which removes the
environment field's offset) the weighted slope of the frequencies against the shifts of
paper-like constants tells each wiring's sign where it is POLARITY_SIGMAS standard errors from
zero (:func:`wiring_polarities`); the fit (:mod:`mows.estimate.calibration.fit_constants`) then
flips the current's sign of a reversed wiring and says so (:func:`polarity_note`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from mows.estimate.calibration.constants import CalibrationPoint, KnownConstants, Wiring
from mows.estimate.calibration.predicted import frequencies, rows_of

POLARITY_SIGMAS = 3.0  # a slope this many standard errors from zero tells the sign
NOMINAL_BETA0_HZ_PER_T = 3.68e3  # the paper's probe: only the sign of a model shift is used


def wiring_polarities(
    points: Sequence[CalibrationPoint], wirings: Mapping[str, Wiring], known: KnownConstants, nominal_lever_m: float
) -> dict[str, int]:
    """+1 or −1 for each wiring whose points tell: the sign of the slope of the measured
    frequencies against the model's frequency shifts of the paper-like constants, within each
    orientation (which removes the environment field's offset). −1: the frequencies move
    against the model, so the wiring's current has the other sign than the table says (a pair
    connected the other way round). A wiring whose slope is within POLARITY_SIGMAS standard
    errors of zero is left out (taken as wired)."""
    if not points:
        return {}
    rows = rows_of(points, wirings, known)
    damping = float(np.mean([p.damping_per_s for p in points]))
    constants = (float(np.median(rows.frequency_hz)), NOMINAL_BETA0_HZ_PER_T)
    idle = dataclasses.replace(rows, field_t=0.0 * rows.field_t, gradient_t_per_m=0.0 * rows.gradient_t_per_m)
    shift = [
        frequencies(r, known, *constants, np.zeros(3), nominal_lever_m, known.theta_stop_rad, damping)
        for r in (rows, idle)
    ]
    model_shift_hz = shift[0] - shift[1]
    weight = 1.0 / rows.frequency_std_hz**2
    wiring = np.array([p.wiring for p in points])
    group = np.round(np.mod(rows.theta0_rad, 2.0 * math.pi), 6)
    polarity: dict[str, int] = {}
    for name in np.unique(wiring):
        sxy = sxx = 0.0
        for theta0 in np.unique(group[wiring == name]):
            rows_in = (wiring == name) & (group == theta0)
            w, x, y = weight[rows_in], model_shift_hz[rows_in], rows.frequency_hz[rows_in]
            dx, dy = x - np.average(x, weights=w), y - np.average(y, weights=w)
            sxy, sxx = sxy + float(np.sum(w * dx * dy)), sxx + float(np.sum(w * dx * dx))
        if sxx > 0.0 and abs(sxy) / math.sqrt(sxx) >= POLARITY_SIGMAS:
            polarity[str(name)] = 1 if sxy > 0.0 else -1
    return polarity


def polarity_note(wiring: str, sign: int) -> str:
    return (
        f"the {wiring!r} wiring is reversed: its frequencies move against its current as written "
        "(the pair is connected the other way round); calibrated with the current's sign flipped"
    )
