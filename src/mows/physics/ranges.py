"""The physical range of every quantity a user gives: one table that every reader checks against.

A value outside its *possible* range is one no bench can produce (a unit error, a typo, a wait
longer than any instrument takes, a buffer larger than any memory): it is refused, naming the
value, the range and the likely cause. A value inside it but outside its *usual* range is
possible on some bench (a cryostat, a strong magnet) but seldom what was meant (°C given as K):
it is said as a warning and used. Tables, probe files, scenarios, hardware files and arguments
all check their numbers here (:func:`check`), so that a quantity has one range wherever it enters.

The bench is the paper's and its kin: a millimetre NdFeB magnet on a cantilever of ~100 Hz, coils
driven by amplifiers of up to 10 A, a field supply of a few ampere, fluxgates centimetres away.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

#: No wait of ours lasts longer than this: a supply's ramp, its settling, an instrument's answer.
MAX_WAIT_S = 600.0


class ImplausibleValue(UserWarning):
    """A possible but unusual value, used as given (the warning says what it may be)."""


@dataclasses.dataclass(frozen=True)
class Range:
    """Where a quantity (in ``unit``) can lie at all (``possible``, bounds included) and where it
    usually lies (``usual``); ``hint``: what a value outside usually is."""

    unit: str
    possible: tuple[float, float]
    usual: tuple[float, float]
    hint: str = ""

    def text(self, bounds: tuple[float, float]) -> str:
        low, high = bounds
        return f"{low:g} … {high:g} {self.unit}".rstrip()


# Magnitudes: a signed quantity is checked by its absolute value.
RANGES: dict[str, Range] = {
    # the probe and where it is
    "temperature_k": Range("K", (1.0, 1000.0), (250.0, 350.0), "a temperature in °C given in K?"),
    "magnet_mass_kg": Range("kg", (1e-9, 1.0), (1e-7, 1e-2), "grams given as kg?"),
    "field_t": Range("T", (0.0, 100.0), (0.0, 0.1), "mT or µT given as T?"),
    "magnet_position_m": Range("m", (0.0, 10.0), (0.0, 2.0), "mm given as m?"),
    "sensor_length_m": Range("m", (1e-4, 1.0), (1e-3, 0.5), "mm given as m?"),
    # the excitation and the supply
    "coil_current_a": Range("A", (0.0, 100.0), (0.0, 10.0), "mA given as A?"),
    "supply_current_a": Range("A", (0.0, 100.0), (0.0, 10.0), "mA given as A?"),
    "slew_a_per_s": Range("A/s", (1e-2, 1e7), (1e-1, 1e5), "a slew in A/ms or mA/s?"),
    "frequency_hz": Range("Hz", (1e-3, 1e6), (1.0, 1e4), "kHz given as Hz?"),
    # a ring-down
    "duration_s": Range("s", (1e-4, 3600.0), (1e-2, 60.0), "ms given as s?"),
    "f_rel_std": Range("", (1e-10, 0.1), (1e-8, 1e-2), "a standard deviation in another unit?"),
    # waits and buffers of the bench (every wait has a deadline; every buffer a size)
    "settle_s": Range("s", (0.0, 60.0), (0.0, 5.0), "ms given as s?"),
    "timeout_s": Range("s", (1e-3, MAX_WAIT_S), (1e-2, 30.0), "ms given as s?"),
    "output_lead_s": Range("s", (1e-3, 10.0), (1e-2, 2.0), "ms given as s?"),
    "block_s": Range("s", (1e-4, 1.0), (1e-3, 0.2), "ms given as s?"),
    "watchdog_s": Range("s", (1e-3, 60.0), (1e-2, 5.0), "ms given as s?"),
    "sample_rate_hz": Range("Hz", (10.0, 1e7), (1e3, 2e6), "kHz given as Hz?"),
}


def check(quantity: str, value: float, name: str = "", warn: bool = True) -> float:
    """``value`` of ``quantity`` (a key of :data:`RANGES`; ``name`` what the user called it):
    ValueError beyond the possible range, an :class:`ImplausibleValue` warning beyond the usual
    (unless not ``warn``)."""
    bounds = RANGES[quantity]
    name = name or quantity
    magnitude = abs(float(value))
    hint = f" ({bounds.hint})" if bounds.hint else ""
    if not math.isfinite(magnitude) or not bounds.possible[0] <= magnitude <= bounds.possible[1]:
        raise ValueError(
            f"{name} = {value:g} {bounds.unit} is beyond any bench: possible {bounds.text(bounds.possible)}{hint}"
        )
    if warn and not bounds.usual[0] <= magnitude <= bounds.usual[1]:
        warnings.warn(
            f"{name} = {value:g} {bounds.unit} is unusual (usually {bounds.text(bounds.usual)}){hint}: used as given",
            ImplausibleValue,
            stacklevel=2,
        )
    return float(value)
