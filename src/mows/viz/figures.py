"""The panels as pictures: what each Foxglove panel shows of a session, drawn with matplotlib
(Agg, no display) from the same channel content a :class:`mows.viz.view.View` produces
(``mows viz BAG --figures DIR``; the images of docs/visualisation.md).

One PNG per panel, from the session's latest content of its channel: ``scene`` (the 3D panel's
arrows, in-plane B and the gradient's principal directions with value ± σ), ``ringdown`` (the
samples with the model from the fit's numbers, Eqs. S2, S11, and the residual), ``sweep`` (mean
Δf against θ0 with ±σ and the decomposition's harmonic series, Eq. 12), ``lab`` (the model
lab's cross-validated rms error and χ²/dof by sweep) and ``excitation`` (each coil's |current|
against the driver's cap over the session). Values stay in SI units on the axes (engineering
prefixes on the ticks), so what is drawn is the channel's numbers as they are: each drawing
returns them, read back from its plot's artists.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import EngFormatter  # noqa: E402

from mows.records import stamps  # noqa: E402
from mows.viz import view as v  # noqa: E402
from mows.viz.scene import Arrow  # noqa: E402

DPI = 80  # small files for the docs (≤ 150 kB each)
COLOURS = {"B": "tab:red", "B∥": "tab:orange", "G": "tab:blue"}  # as the 3D panel's (mows.viz.channels)


@dataclass
class Panels:
    """Each panel's latest content in a session (the excitation: all of it, with its log times)."""

    scene: dict[str, list[Arrow]] | None = None
    ringdown: v.RingdownPlot | None = None
    sweep: v.SweepPlot | None = None
    lab: v.LabHistory | None = None
    excitation: list[tuple[int, v.ExcitationPlot]] = field(default_factory=list)

    @classmethod
    def of(cls, shown: Iterable[v.Shown]) -> Panels:
        panels = cls()
        for item in shown:
            if item.topic == v.EXCITATION:
                panels.excitation.append((item.log_time_ns, item.content))  # type: ignore[arg-type]
            elif item.topic in LATEST:
                setattr(panels, LATEST[item.topic], item.content)
        return panels

    def names(self) -> list[str]:
        """The panels with something to draw, in :data:`DRAWINGS` order."""
        return [name for name in DRAWINGS if (self.excitation if name == "excitation" else getattr(self, name))]


LATEST = {v.SCENE: "scene", v.RINGDOWN: "ringdown", v.SWEEP: "sweep", v.LAB: "lab"}


@dataclass(frozen=True)
class Drawn:
    """One panel's picture: the PNG's bytes and the numbers it draws, by name."""

    png: bytes
    data: dict[str, np.ndarray]


def draw(panels: Panels, name: str) -> Drawn:
    """Panel ``name`` (one of :meth:`Panels.names`) as a PNG and the numbers it drew."""
    if name not in panels.names():
        raise ValueError(f"panel = {name!r}: nothing to draw; the session has {', '.join(panels.names()) or 'none'}")
    figure, data = DRAWINGS[name](panels)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(figure)
    return Drawn(buffer.getvalue(), data)


def _xy(line) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)


def scene_figure(panels: Panels) -> tuple[Figure, dict[str, np.ndarray]]:
    """The 3D panel's arrows, each from its tail along its direction by its length, labelled."""
    arrows = [arrow for entity in (panels.scene or {}).values() for arrow in entity]
    figure = plt.figure(figsize=(5.5, 5))
    axis = figure.add_subplot(projection="3d")
    tails = np.array([a.tail_m for a in arrows], float).reshape(-1, 3)
    vectors = np.array([np.asarray(a.direction) * a.length_m for a in arrows], float).reshape(-1, 3)
    for arrow, tail, vector in zip(arrows, tails, vectors):
        axis.quiver(*tail, *vector, color=COLOURS[arrow.kind], arrow_length_ratio=0.2, linewidth=2)
        if arrow.label:
            axis.text(*(tail + vector), arrow.label, color=COLOURS[arrow.kind], fontsize=8)
    reach = float(np.max(np.abs(np.concatenate([tails, tails + vectors])), initial=0.0)) or 1.0
    axis.set(xlim=(-reach, reach), ylim=(-reach, reach), zlim=(-reach, reach))
    axis.set(xlabel="x (m)", ylabel="y (m)", zlabel="z (m)")
    frames = sorted({a.frame_id for a in arrows})
    axis.set_title(f"/mows/viz/scene in {', '.join(frames)}: B red, principal gradients blue", fontsize=9)
    return figure, {"tail_m": tails, "vector_m": vectors}


def ringdown_figure(panels: Panels) -> tuple[Figure, dict[str, np.ndarray]]:
    """The ring-down's samples and model above, the residual below (its own scale)."""
    plot = panels.ringdown
    assert plot is not None
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True, height_ratios=(2, 1))
    (data,) = top.plot(plot.t_s, plot.data_t, ".", ms=1.5, color="k", label="samples")
    (model,) = top.plot(plot.t_s, plot.model_t, "-", lw=0.8, color="tab:red", label="model (fit's numbers)")
    (residual,) = bottom.plot(plot.t_s, plot.residual_t, ".", ms=1.5, color="tab:gray")
    top.legend(loc="upper right", fontsize=8)
    top.set_title(
        f"/mows/viz/ringdown: cycle {plot.cycle_id}, f = {plot.frequency_hz:.4f} ± {plot.frequency_std_hz:.1e} Hz",
        fontsize=9,
    )
    top.set_ylabel("signal")
    bottom.set(xlabel="t from the window's start", ylabel="residual")
    for axis in (top, bottom):
        axis.yaxis.set_major_formatter(EngFormatter(unit="T"))
    bottom.xaxis.set_major_formatter(EngFormatter(unit="s"))
    t_s, data_t = _xy(data)
    return figure, {"t_s": t_s, "data_t": data_t, "model_t": _xy(model)[1], "residual_t": _xy(residual)[1]}


def sweep_figure(panels: Panels) -> tuple[Figure, dict[str, np.ndarray]]:
    """Mean Δf at each θ0 with ±σ bars and the decomposition's curve."""
    plot = panels.sweep
    assert plot is not None
    shift = np.asarray(plot.frequency_shift_hz)
    bars = [shift - np.asarray(plot.lower_hz), np.asarray(plot.upper_hz) - shift]
    figure, axis = plt.subplots(figsize=(7, 4))
    points = axis.errorbar(plot.theta0_deg, shift, bars, fmt="o", ms=4, capsize=3, color="k", label="mean Δf ± σ")
    (curve,) = axis.plot(plot.curve_theta0_deg, plot.curve_shift_hz, "-", color="tab:red", label="Eq. 12")
    axis.yaxis.set_major_formatter(EngFormatter(unit="Hz"))
    axis.set(xlabel="θ0 (deg)", ylabel="Δf", xticks=np.arange(0, 361, 60))
    axis.set_title(
        f"/mows/viz/sweep: sweep {plot.sweep_id}, probe {plot.probe_id}, χ²/dof {plot.chi2_dof:.2g}", fontsize=9
    )
    axis.legend(fontsize=8)
    theta0_deg, drawn_shift = _xy(points.lines[0])
    (segments,) = points.lines[2]
    ends = np.array([np.asarray(path.vertices, float)[:, 1] for path in segments.get_paths()])
    curve_theta0_deg, curve_shift_hz = _xy(curve)
    return figure, {
        "theta0_deg": theta0_deg,
        "frequency_shift_hz": drawn_shift,
        "lower_hz": ends.min(axis=1),
        "upper_hz": ends.max(axis=1),
        "curve_theta0_deg": curve_theta0_deg,
        "curve_shift_hz": curve_shift_hz,
    }


def lab_figure(panels: Panels) -> tuple[Figure, dict[str, np.ndarray]]:
    """The lab's cross-validated rms error and χ²/dof after each sweep."""
    history = panels.lab
    assert history is not None
    figure, (left, right) = plt.subplots(1, 2, figsize=(8, 3.2))
    (cv,) = left.plot(history.sweep_id, history.cv_rms_hz, "o-", color="tab:orange")
    (chi2,) = right.plot(history.sweep_id, history.chi2_dof, "o-")
    left.yaxis.set_major_formatter(EngFormatter(unit="Hz"))
    left.set(xlabel="sweep", ylabel="cross-validated rms error")
    right.set(xlabel="sweep", ylabel="χ²/dof", yscale="log")
    for axis in (left, right):
        axis.set_xticks(history.sweep_id)
    figure.suptitle(f"/mows/viz/lab: verdict {history.verdict}", fontsize=9)
    sweeps, cv_rms_hz = _xy(cv)
    return figure, {"sweep_id": sweeps, "cv_rms_hz": cv_rms_hz, "chi2_dof": _xy(chi2)[1]}


def excitation_figure(panels: Panels) -> tuple[Figure, dict[str, np.ndarray]]:
    """Each coil's |current| from one excitation state to the next, against the driver's cap."""
    first_ns = panels.excitation[0][0]
    time_s = np.array([(t - first_ns) / stamps.NS_PER_S for t, _ in panels.excitation])
    currents = np.array([plot.coil_current_a for _, plot in panels.excitation], float)
    cap = panels.excitation[-1][1].coil_current_cap_a
    figure, axis = plt.subplots(figsize=(7, 3.2))
    lines = [
        axis.step(time_s, currents[:, coil], where="post", label=f"coil {coil + 1}")[0]
        for coil in range(currents.shape[1])
    ]
    axis.axhline(cap, color="tab:red", ls="--", lw=0.8, label="cap")
    axis.set_ylim(0, 1.1 * cap)
    axis.yaxis.set_major_formatter(EngFormatter(unit="A"))
    axis.xaxis.set_major_formatter(EngFormatter(unit="s"))
    axis.set(xlabel="session time", ylabel="|current|")
    phases = " → ".join(dict.fromkeys(plot.phase_name for _, plot in panels.excitation))
    axis.set_title(f"/mows/viz/excitation: {phases}", fontsize=9)
    axis.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    drawn = np.column_stack([_xy(line)[1] for line in lines])
    return figure, {"time_s": _xy(lines[0])[0], "coil_current_a": drawn, "cap_a": np.array([cap])}


DRAWINGS: dict[str, Callable[[Panels], tuple[Figure, dict[str, np.ndarray]]]] = {
    "scene": scene_figure,
    "ringdown": ringdown_figure,
    "sweep": sweep_figure,
    "lab": lab_figure,
    "excitation": excitation_figure,
}
