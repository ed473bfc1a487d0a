"""**View**: the graph's messages in, what each Foxglove channel shows out (I/O-free).

Fed the graph's topics (rclpy's messages or a bag's, read by attribute: the same fields), a
View returns :class:`Shown` items, each a channel's content at a log time: the scene (the
probes' arrows, :mod:`mows.viz.scene`), the mount's frames (:mod:`mows.viz.mount`), and the
plots as dataclasses of numbers and lists (JSON on the channel, :mod:`mows.viz.channels`).
The raw stream is kept ``buffer_s`` long, so that a ring-down's fit, which arrives after its
samples, is drawn over them; a fit that comes before the last of its samples waits for them.
The stream itself is shown averaged down to ``raw_rate_hz``.

With several probes in one window each fit is drawn over the window's samples with its own
model, so its residual holds the other probes' tones.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mows.estimate.segments import block_from_message
from mows.records import stamps
from mows.records.samples import SampleBlock
from mows.viz.curves import RingdownModel, ringdown_curve, stride, sweep_curve_hz
from mows.viz.mount import FrameTransform, Mount
from mows.viz.scene import ARROW_LENGTH_M, Arrow, ProbeField, axis_arrow, probe_arrows
from mows.viz.workspace_scene import workspace_arrows

# The channels' topics (docs/visualisation.md), beside the graph's own under /mows/.
SCENE, FRAMES = "/mows/viz/scene", "/mows/viz/frames"
RAW, RINGDOWN, SWEEP = "/mows/viz/raw", "/mows/viz/ringdown", "/mows/viz/sweep"
LAB, EXCITATION, DIAGNOSTICS = "/mows/viz/lab", "/mows/viz/excitation", "/mows/viz/diagnostics"
STATUS_OK = 0  # RingdownFit, FieldEstimate, SweepDecomposition, ProbeField


@dataclass(frozen=True)
class ViewSettings:
    channels: str = "difference"  # what the estimator fitted (its ``channels``)
    raw_rate_hz: float = 1000.0  # the raw stream's plotted rate
    # raw samples kept for the ring-downs' plots: a fit later than this is not drawn (a loaded
    # host's graph at the default priority published fits up to 9.6 s late, docs/performance.md)
    buffer_s: float = 20.0
    max_points: int = 2000  # points of one ring-down's plot
    coil_current_cap_a: float = 10.0  # the driver's coil_current_cap_a
    arrow_length_m: float = ARROW_LENGTH_M

    def __post_init__(self) -> None:
        if not self.raw_rate_hz > 0:
            raise ValueError(f"raw_rate_hz = {self.raw_rate_hz} must be positive")
        if not self.buffer_s > 0:
            raise ValueError(f"buffer_s = {self.buffer_s} must be positive")
        if not self.coil_current_cap_a > 0:
            raise ValueError(f"coil_current_cap_a = {self.coil_current_cap_a} must be positive")


# --- what the plots show (JSON on the channel) ---------------------------------------------
@dataclass(frozen=True)
class RawSample:
    """One sample of the stream, averaged over raw_rate_hz's interval, tesla."""

    near_t: float
    far_t: float
    difference_t: float


@dataclass(frozen=True)
class RingdownPlot:
    """One ring-down: the fitted samples, the model from the fit's numbers and the residual."""

    cycle_id: int
    repeat_index: int
    probe_id: int
    status_name: str
    frequency_hz: float
    frequency_std_hz: float
    t_s: list[float]
    data_t: list[float]
    model_t: list[float]
    residual_t: list[float]


@dataclass(frozen=True)
class SweepPlot:
    """One probe's sweep: mean Δf at each θ0 with ±σ, and the decomposition's curve (Eq. 12)."""

    sweep_id: int
    probe_id: int
    status: int
    theta0_deg: list[float]
    frequency_shift_hz: list[float]
    lower_hz: list[float]
    upper_hz: list[float]
    curve_theta0_deg: list[float]
    curve_shift_hz: list[float]
    rms_residual_hz: float
    chi2_dof: float


@dataclass(frozen=True)
class LabHistory:
    """The model lab's error after every sweep so far, and its latest verdict."""

    sweep_id: list[int]
    cv_rms_hz: list[float]
    chi2_dof: list[float]
    bic: list[float]
    effects: list[int]
    verdict: str
    structure: str


@dataclass(frozen=True)
class ExcitationPlot:
    """The coil phase, and each coil's |current| against the driver's cap."""

    phase_name: str
    cycle_id: int
    coils_on: bool
    frequency_hz: float
    theta0_deg: float
    coil_current_a: list[float]
    coil_current_cap_a: float
    share_of_cap: list[float]


@dataclass(frozen=True)
class DiagnosticLine:
    name: str
    level: int
    message: str
    values: str  # "key=value" lines


@dataclass(frozen=True)
class DiagnosticsTable:
    statuses: list[DiagnosticLine]


@dataclass(frozen=True)
class Shown:
    """What channel ``topic`` shows from ``log_time_ns``: arrows by entity id (the scene),
    frames (the mount), or a plot's dataclass."""

    topic: str
    log_time_ns: int
    content: object


@dataclass(frozen=True)
class RingdownToDraw:
    """A fit with its window's samples (rows: samples, columns: fluxgates), ready to draw: the
    drawing (the model where θmax is undetermined, :mod:`mows.viz.curves`) may take seconds,
    so a live server does it off the stream's thread."""

    fit: object  # the RingdownFit message
    model: RingdownModel
    log_time_ns: int
    samples_t: np.ndarray
    sample_rate_hz: float

    def drawn(self, settings: ViewSettings) -> Shown:
        every = stride(len(self.samples_t), settings.max_points)
        curve = ringdown_curve(self.samples_t, self.sample_rate_hz, self.model, settings.channels, every)
        msg: Any = self.fit
        plot = RingdownPlot(
            int(msg.cycle_id),
            int(msg.repeat_index),
            int(msg.probe_id),
            str(msg.status_name),
            float(msg.frequency_hz),
            float(msg.frequency_std_hz),
            *(_listed(values) for values in (curve.t_s, curve.data_t, curve.model_t, curve.residual_t)),
        )
        return Shown(RINGDOWN, self.log_time_ns, plot)


@dataclass
class View:
    """Module docstring. ``mount``: the probe mount's URDF text, or None for no frames."""

    settings: ViewSettings = ViewSettings()
    mount: Mount | None = None
    _blocks: deque = field(default_factory=deque)
    _carry: list = field(default_factory=list)  # samples not yet averaged into a raw point
    _entities: dict[str, list[Arrow]] = field(default_factory=dict)
    _fields: dict[int, ProbeField] = field(default_factory=dict)
    _history: list = field(default_factory=list)
    _fits: list = field(default_factory=list)  # (fit message, model, log time) waiting for samples
    fits_without_samples: int = 0  # OK fits not drawn: none of their samples was kept

    # --- the stream ----------------------------------------------------------------------
    def on_raw(self, msg) -> list[Shown]:
        """The stream's points, then the ring-downs whose samples this block completes, drawn."""
        return self.raw_points(msg) + self._drawn()

    def raw_points(self, msg) -> list[Shown]:
        """The stream's points of one block, kept for the ring-downs (cheap: a live server's
        stream thread calls this, and draws :meth:`ready_ringdowns` elsewhere)."""
        block = block_from_message(msg)
        self._keep(block)
        step = max(1, round(block.sample_rate_hz / self.settings.raw_rate_hz))
        samples = block.samples_t[:, :2] if block.samples_t.shape[1] >= 2 else np.repeat(block.samples_t, 2, axis=1)
        shown = []
        # Whole intervals of ``step`` samples from the block's first, averaged, stamped at their first.
        for start in range(0, len(block) - step + 1, step):
            near, far = samples[start : start + step].mean(axis=0)
            stamp = block.stamp_of(block.first_sample_index + start)
            shown.append(Shown(RAW, stamp, RawSample(float(near), float(far), float(near - far))))
        return shown

    def _keep(self, block: SampleBlock) -> None:
        self._blocks.append(block)
        horizon = block.stamp_ns - round(self.settings.buffer_s * stamps.NS_PER_S)
        while self._blocks and self._blocks[0].stamp_of(self._blocks[0].end_index) < horizon:
            self._blocks.popleft()

    def window(self, start_ns: int, n_samples: int) -> tuple[np.ndarray, float] | None:
        """The kept samples of ``n_samples`` from device time ``start_ns`` (NaN where missing)
        and their rate; None when none of them is kept."""
        if not self._blocks:
            return None
        rate = self._blocks[-1].sample_rate_hz
        first = self._blocks[-1].index_at(start_ns)
        samples = np.full((n_samples, self._blocks[-1].samples_t.shape[1]), np.nan)
        found = False
        for block in self._blocks:
            lo, hi = max(first, block.first_sample_index), min(first + n_samples, block.end_index)
            if lo < hi and block.sample_rate_hz == rate:
                samples[lo - first : hi - first] = block.samples_t[
                    lo - block.first_sample_index : hi - block.first_sample_index
                ]
                found = True
        return (samples, rate) if found else None

    # --- results -------------------------------------------------------------------------
    def on_ringdown(self, msg, time_ns: int) -> list[Shown]:
        """The ring-downs whose samples are all here, this one among them once its are, drawn."""
        self.keep_fit(msg, time_ns)
        return self._drawn()

    def keep_fit(self, msg, time_ns: int) -> None:
        """A fit to draw once the stream has passed its window (it may come before its samples)."""
        model = RingdownModel.of(msg)
        if msg.status == STATUS_OK and model.drawable:
            self._fits.append((msg, model, time_ns))

    def ready_ringdowns(self) -> list[RingdownToDraw]:
        """The kept fits whose window the stream has passed, with a copy of their samples (NaN
        where a block is missing); a fit whose samples are no longer kept is left out, counted."""
        if not self._blocks:
            return []
        newest = self._blocks[-1]
        ready, waiting = [], []
        for msg, model, time_ns in self._fits:
            start_ns, n_samples = stamps.nanoseconds(msg.header.stamp), int(msg.n_samples)
            if newest.index_at(start_ns) + n_samples > newest.end_index:
                waiting.append((msg, model, time_ns))
                continue
            kept = self.window(start_ns, n_samples)
            if kept is not None:
                ready.append(RingdownToDraw(msg, model, time_ns, *kept))
            else:
                self.fits_without_samples += 1
        self._fits = waiting
        return ready

    def _drawn(self) -> list[Shown]:
        return [window.drawn(self.settings) for window in self.ready_ringdowns()]

    def on_field(self, msg, time_ns: int) -> list[Shown]:
        """A ring-down's field along the probe axis, an arrow in its probe frame."""
        if msg.status != STATUS_OK or not math.isfinite(msg.field_along_axis_t):
            return []
        frame = msg.header.frame_id
        arrow = axis_arrow(frame, msg.field_along_axis_t, msg.field_along_axis_std_t, self.settings.arrow_length_m)
        self._entities[f"{frame}/axis"] = [arrow]
        return [self._scene(time_ns)]

    def on_sweep(self, msg, time_ns: int) -> list[Shown]:
        theta = np.asarray(msg.theta0_rad, float)
        shift, std = np.asarray(msg.frequency_shift_hz, float), np.asarray(msg.frequency_shift_std_hz, float)
        grid = np.linspace(0.0, 2 * math.pi, 181)
        ok = msg.status == STATUS_OK and len(msg.harmonic_amplitude_hz) > 0
        curve = sweep_curve_hz(msg.harmonic_amplitude_hz, msg.harmonic_phase_rad, grid) if ok else np.array([])
        plot = SweepPlot(
            int(msg.sweep_id),
            int(msg.probe_id),
            int(msg.status),
            _listed(np.degrees(theta)),
            _listed(shift),
            _listed(shift - std),
            _listed(shift + std),
            _listed(np.degrees(grid) if ok else np.array([])),
            _listed(curve),
            float(msg.rms_residual_hz),
            float(msg.chi2_dof),
        )
        shown = [Shown(SWEEP, time_ns, plot)]
        if msg.status == STATUS_OK:
            self._fields[int(msg.probe_id)] = ProbeField.of(msg, msg.header.frame_id)
            shown.append(self._scene(time_ns))
        return shown

    def on_field_map(self, msg, time_ns: int) -> list[Shown]:
        """Every probe of a map at its place in the map's frame (replacing its sweep's arrows)."""
        for probe in msg.probes:
            if probe.status == STATUS_OK:
                self._fields[int(probe.probe_id)] = ProbeField.of(probe, msg.header.frame_id, probe.position_m)
        return [self._scene(time_ns)]

    def on_workspace_model(self, msg, time_ns: int) -> list[Shown]:
        """The workspace map's field on a grid and its poses (replacing an earlier map's)."""
        self._entities.update(workspace_arrows(msg))
        return [self._scene(time_ns)]

    def _scene(self, time_ns: int) -> Shown:
        for probe_id, arrows in probe_arrows(list(self._fields.values()), self.settings.arrow_length_m).items():
            self._entities[f"probe_{probe_id}/field"] = arrows
        return Shown(SCENE, time_ns, dict(self._entities))

    def on_model_report(self, msg, time_ns: int) -> list[Shown]:
        self._history = [entry for entry in self._history if entry[0] != int(msg.sweep_id)]
        self._history.append(
            (int(msg.sweep_id), float(msg.cv_rms_hz), float(msg.chi2_dof), float(msg.bic), len(msg.effects))
        )
        sweeps, cv_rms, chi2, bic, effects = (list(column) for column in zip(*self._history))
        history = LabHistory(sweeps, cv_rms, chi2, bic, effects, str(msg.verdict), str(msg.structure))
        return [Shown(LAB, time_ns, history)]

    # --- state ---------------------------------------------------------------------------
    def on_excitation(self, msg, time_ns: int) -> list[Shown]:
        currents = [abs(float(a)) for a in msg.coil_current_amplitude_a]
        cap = self.settings.coil_current_cap_a
        plot = ExcitationPlot(
            str(msg.phase_name),
            int(msg.cycle_id),
            bool(msg.coils_on),
            float(msg.frequency_hz),
            math.degrees(msg.theta0_rad),
            currents,
            cap,
            [a / cap for a in currents],
        )
        return [Shown(EXCITATION, time_ns, plot)]

    def on_joint_states(self, msg, time_ns: int) -> list[Shown]:
        if self.mount is None:
            return []
        positions = {name: float(p) for name, p in zip(msg.name, msg.position)}
        frames: list[FrameTransform] = self.mount.transforms(positions)
        return [Shown(FRAMES, time_ns, frames)]

    def on_diagnostics(self, msg, time_ns: int) -> list[Shown]:
        lines = [
            DiagnosticLine(
                str(s.name),
                s.level[0] if isinstance(s.level, bytes) else int(s.level),
                str(s.message),
                "\n".join(f"{v.key}={v.value}" for v in s.values),
            )
            for s in msg.status
        ]
        return [Shown(DIAGNOSTICS, time_ns, DiagnosticsTable(lines))]


def _listed(values) -> list[float]:
    return np.asarray(values, float).tolist()
