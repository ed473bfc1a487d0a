"""The simulated device of a scene with several probes, its commands taking effect at chosen
sample indices: :class:`mows.device.simulated.scheduled.ScheduledDevice` over
:class:`mows.sim.multiprobe_device.MultiProbeDevice`.

The scene's probes sit on one shared stage: a turn to the stage angle θ turns every probe to
its home orientation plus θ. The coils are driven by the sum of the probes' tones
(:class:`mows.device.interface.MultiToneCommand`), checked against the cap on the summed true
peak (:func:`mows.physics.multitone.peak_current_a`) over the whole excitation where it is
scheduled, so that nothing above the cap is ever queued; a switch-off (coils of zero
amplitude, an emergency stop) switches every tone off at once. The device has no field supply.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np

from mows.device.simulated.scheduled import OverCap, ScheduledDevice
from mows.physics.coils import CurrentCap
from mows.physics.multitone import Tone, peak_current_a
from mows.sim.multiprobe_device import MultiProbeBlock, MultiProbeDevice

NO_SUPPLY = "the simulator of several probes has no field supply"


class ScheduledMultiProbeDevice(ScheduledDevice):
    """``device`` (all probes on one shared stage) with a command queue; ``cap`` is the driver's
    coil current cap. ``peak_current_a`` is the largest coil current the device carried."""

    device: MultiProbeDevice  # type: ignore[assignment]

    def __init__(
        self,
        device: MultiProbeDevice,
        cap: CurrentCap,
        supply_cap_a: float = math.inf,
        supply_slew_a_per_s: float = math.inf,
    ):
        stages = {p.stage for p in device.scenario.probes}
        if len(stages) != 1:
            raise ValueError(
                f"scenario {device.scenario.name!r}: its probes are on the stages {sorted(stages)}; "
                "the driver turns one shared stage"
            )
        super().__init__(device, cap, supply_cap_a, supply_slew_a_per_s)  # type: ignore[arg-type]
        self.home = tuple(device.scenario.placed_probes())
        self.peak_current_a = 0.0

    @staticmethod
    def _supply_of(device):
        return None

    def _turn(self, theta0_rad: float) -> None:
        self.device.set_orientations([p.pose.theta0_rad + theta0_rad for p in self.home])

    def schedule_coils(self, at_index: int, amplitudes_a, frequency_hz: float) -> int:
        """Switch every tone off at ``at_index`` (all amplitudes zero); ValueError for a drive of
        one tone, which this device takes as tones (:meth:`schedule_tones`)."""
        amplitudes = self.check_coils(amplitudes_a, frequency_hz)
        if any(amplitudes):
            raise ValueError("the device of several probes is driven by its probes' tones, not by coil amplitudes")
        return self._enqueue(at_index, "off", functools.partial(self._drive, amplitudes, 0.0))

    def check_tones(self, tones: Sequence[Tone], samples: int) -> tuple[Tone, ...]:
        """The tones as a tuple if the device can take them for ``samples`` samples; OverCap when
        their summed peak is above the cap, ValueError for anything else malformed."""
        tones = tuple(tones)
        ids = [t.probe_id for t in tones] if all(isinstance(t, Tone) for t in tones) else None
        if not tones or ids is None or len(set(ids)) != len(ids) or not set(ids) <= set(range(len(self.home))):
            raise ValueError(f"tones {tones!r} must be Tones of distinct probes 0 to {len(self.home) - 1}")
        if not (isinstance(samples, (int, np.integer)) and samples > 0):
            raise ValueError(f"samples = {samples!r} must be an integer > 0")
        nyquist_hz = self.device.sample_rate_hz / 2.0
        for t in tones:
            if t.frequency_hz >= nyquist_hz:
                raise ValueError(f"tone of probe {t.probe_id}: {t.frequency_hz!r} Hz must be below {nyquist_hz:g} Hz")
        try:
            peak = float(peak_current_a(self.device.setup, tones, samples / self.device.sample_rate_hz).max())
        except ValueError as alone:  # one tone alone above the setup's cap
            raise OverCap(str(alone)) from None
        if peak > self.cap.limit_a:
            raise OverCap(f"the tones of probes {ids} peak at {peak:.6g} A, above the {self.cap.limit_a:g} A cap")
        return tones

    def schedule_tones(self, at_index: int, tones: Sequence[Tone], samples: int) -> int:
        """Drive the coils with the sum of ``tones`` for ``samples`` samples from ``at_index``;
        returns the sample it applies at. OverCap above the cap, ValueError for a malformed
        drive; RuntimeError while a turn of the stage waits."""
        checked = self.check_tones(tones, samples)
        if any(entry[2] == "turn" for entry in self._queue):
            raise RuntimeError("coils cannot go on while a turn of the probes is waiting")
        return self._enqueue(at_index, "on", functools.partial(self._drive_tones, checked, int(samples)))

    def schedule_field_current(self, at_index: int, current_a: float) -> int:
        raise ValueError(NO_SUPPLY)

    def _drive_tones(self, tones: tuple[Tone, ...], samples: int) -> None:
        self.device.drive(tones, self.device.sample_index + samples)
        self.coils_on = True

    def _drive(self, amplitudes_a: tuple, frequency_hz: float) -> None:
        self.device.emergency_stop()
        self.coils_on = False

    def _log_coils(self, block: MultiProbeBlock) -> None:  # type: ignore[override]
        super()._log_coils(block)  # type: ignore[arg-type]
        if block.currents_a.size:
            self.peak_current_a = max(self.peak_current_a, float(np.max(np.abs(block.currents_a))))
