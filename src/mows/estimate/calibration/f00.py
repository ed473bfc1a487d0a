"""The zero-field frequency f00 calibrated from ring-downs in a known field along the probe axis.

Eq. 6 with no gradient, f = f00·√(1 + m·B/kM), solved for f00 per ring-down and averaged. An
I/O-free state machine in the manner of :class:`mows.device.cycle.sequencer.CycleSequencer`: fed the
frequencies of OK ring-downs (:meth:`F00Calibration.offer`) and the end of its time
(:meth:`F00Calibration.time_up`), it returns the outcome once it has one.
"""

import dataclasses
import enum
import math

import numpy as np

from mows.physics.probe import Probe


class CalibrationStatus(enum.Enum):
    OK = "ok"
    TOO_FEW_RINGDOWNS = "too few OK ring-downs before the time limit"


@dataclasses.dataclass(frozen=True)
class F00Outcome:
    """A finished calibration (a :class:`mows.records.results.Result`): f00 ± σ (NaN unless
    ``ok``) from ``n_used`` ring-downs."""

    status: CalibrationStatus
    message: str
    f00_hz: float = math.nan
    f00_std_hz: float = math.nan
    n_used: int = 0

    @property
    def ok(self) -> bool:
        return self.status is CalibrationStatus.OK

    def report(self) -> str:
        return self.message


class F00Calibration:
    """Collects ``n_ringdowns`` OK ring-downs of ``probe`` in ``reference_field_t`` (along the
    probe axis, T) and solves each for f00.

    ValueError, with the reason, when the request cannot be met: fewer than one ring-down, a
    time limit that is not positive, or a field at or beyond spring cancellation (−kM/m), where
    the probe has no restoring torque and Eq. 6 no real root.
    """

    def __init__(self, probe: Probe, reference_field_t: float, n_ringdowns: int, timeout_s: float) -> None:
        # f/f00 = √ratio: the field adds m·B to the spring kM (Eq. 6, kG = 0).
        self._ratio = 1.0 + probe.moment_am2 * reference_field_t / probe.spring_nm_per_rad
        if n_ringdowns < 1 or not timeout_s > 0 or not self._ratio > 0:
            raise ValueError(
                f"need n_ringdowns ≥ 1, timeout_s > 0 and a reference field above spring "
                f"cancellation (−kM/m = {probe.cancellation_field_t * 1e3:.2f} mT)"
            )
        self.wanted = int(n_ringdowns)
        self.timeout_s = float(timeout_s)
        self._fits: list[tuple[float, float]] = []
        self.outcome: F00Outcome | None = None

    @property
    def done(self) -> bool:
        return self.outcome is not None

    def offer(self, frequency_hz: float, frequency_std_hz: float) -> F00Outcome | None:
        """One OK ring-down's frequency ± σ; the outcome once ``n_ringdowns`` are in."""
        if self.done:
            return None
        self._fits.append((float(frequency_hz), float(frequency_std_hz)))
        if len(self._fits) >= self.wanted:
            self.outcome = self._solve()
        return self.outcome

    def time_up(self) -> F00Outcome | None:
        """The time limit passed: a failure naming how many ring-downs came (None if done)."""
        if self.done:
            return None
        n = len(self._fits)
        self.outcome = F00Outcome(
            CalibrationStatus.TOO_FEW_RINGDOWNS,
            f"only {n} of {self.wanted} OK ring-downs in {self.timeout_s} s",
            n_used=n,
        )
        return self.outcome

    def _solve(self) -> F00Outcome:
        """f00 per ring-down and their mean; σ is the larger of the scatter of the mean and the
        fits' own σ propagated (a few ring-downs estimate their scatter poorly)."""
        fits = np.array(self._fits, float)
        n = len(fits)
        scale = 1.0 / math.sqrt(self._ratio)
        f00_each = fits[:, 0] * scale
        spread = f00_each.std(ddof=1) / math.sqrt(n) if n > 1 else 0.0
        propagated = math.sqrt(np.sum((fits[:, 1] * scale) ** 2)) / n
        f00, std = float(f00_each.mean()), float(max(spread, propagated))
        return F00Outcome(
            CalibrationStatus.OK, f"f00 = {f00:.6f} ± {std * 1e3:.4f} mHz from {n} ring-downs", f00, std, n
        )
