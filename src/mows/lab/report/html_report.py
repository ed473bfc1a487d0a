"""The lab's HTML report: one self-contained page, plots by matplotlib (Agg): the residuals and the
terms found beyond the catalog as inline SVG, the others as PNG embedded as base64.

Plots: model against measurement in the style of the paper's Fig. 3 (Δf against the field
along the probe axis) and Fig. 4 (polar plot of |Δf(θ0)| with its decomposition into the
field part, harmonic 1, and the gradient part, harmonic 2); residuals of the base and final
model on separate axes (each on its own scale) and the final model's pulls, against θ0 and
against every covariate, first those the diagnosis names (a significant trend of the residual,
a factor of a term found beyond the catalog); the ranked candidates with their alias groups (exact physical aliases
in words and numbers); the terms found beyond the catalog, each beside the residual it explains,
with the strongest one's plugin; the error history (χ²/dof and cross-validated rms per step). Legends
sit outside the data.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import io
import os
import pathlib
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from mows.lab.data.table import LABELS, PROBE

if TYPE_CHECKING:
    from types import ModuleType

    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mows.lab.data.table import MeasurementTable
    from mows.lab.diagnosis.discovery import DiscoveredTerm
    from mows.lab.model.least_squares import FitResult
    from mows.lab.report.lab_report import LabReport
    from mows.physics.schema import FloatOrArray


RASTER_ROWS = 2000  # more points than this: an SVG's markers are drawn as one image, so the page stays small


def _pyplot() -> ModuleType:
    """matplotlib's pyplot on the Agg backend, imported at the first drawing: every node and
    command that imports the lab would otherwise pay its ~0.3 s of import at start-up."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot

    return matplotlib.pyplot


def _svg(figure: Figure) -> str:
    """The figure as an ``<svg>`` element to inline in the page (text as text, not as glyph paths)."""
    buffer = io.StringIO()
    with _pyplot().rc_context({"svg.fonttype": "none"}):
        figure.savefig(buffer, format="svg", bbox_inches="tight")
    _pyplot().close(figure)
    text = buffer.getvalue()
    return text[text.index("<svg") :]


def _png(figure: Figure) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90, bbox_inches="tight")
    _pyplot().close(figure)
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode()


def _shift_hz(fit: FitResult) -> tuple[np.ndarray, np.ndarray]:
    """Measured and model Δf = f − f00 (each row's probe's fitted f00), Hz."""
    f00 = fit.row_f00_hz
    return fit.table.f_hz - f00, fit.prediction_hz - f00


def figure_field_response(report: LabReport) -> str:
    """Fig. 3 style: Δf against Bx' (reference field along the probe axis).

    The models are drawn as markers at the measured rows, not as lines: Δf also follows B⊥ and
    the gradient, so it is not a function of Bx' alone and a line through sorted Bx' zigzags.
    """
    fit, base = report.fit, report.base
    table = fit.table
    along_ut = table.probe_field_t[:, 0] * 1e6
    measured, model = _shift_hz(fit)
    _, base_model = _shift_hz(base)
    figure, axis = _pyplot().subplots(figsize=(6, 4))
    axis.errorbar(along_ut, measured * 1e3, table.f_std_hz * 1e3, fmt=".", color="k", label="measured")
    axis.plot(along_ut, base_model * 1e3, "x", color="tab:gray", label="Eq. 6 (base)")
    axis.plot(along_ut, model * 1e3, "o", mfc="none", color="tab:red", label=report.model)
    axis.set(
        xlabel="Bx' reference field along the probe axis (µT)",
        ylabel="Δf = f − f00 (mHz)",
        title="Frequency shift against field (cf. paper Fig. 3)",
    )
    axis.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=3, fontsize=8)
    return _png(figure)


def _largest_sweep(table: MeasurementTable) -> np.ndarray:
    """Rows of the sweep with the most rows: one sweep is one reference field and gradient; of a
    table of several probes, the first probe's rows of it."""
    ids, counts = np.unique(table.sweep_ids, return_counts=True)
    rows = table.sweep_ids == ids[np.argmax(counts)]
    return rows & (table.probe == np.min(table.probe)) if table.has(PROBE) else rows


def sweep_curve(fit: FitResult, rows: np.ndarray, theta0_deg: FloatOrArray) -> np.ndarray:
    """The fitted model's f (Hz) at orientations ``theta0_deg`` of the sweep ``rows``.

    Every other column (reference field, start amplitude, time, temperature…) is interpolated
    periodically in θ0 between the sweep's measured orientations (repeats averaged), so the
    curve passes through the model's value at every measured orientation. The labels (sweep,
    probe, step) keep the sweep's first row's.
    """
    sweep = fit.table.subset(rows)
    angles, inverse = np.unique(np.mod(sweep.theta0_deg, 360.0), return_inverse=True)
    counts = np.bincount(inverse)
    grid = np.asarray(theta0_deg, float)
    columns = {
        name: np.interp(np.mod(grid, 360.0), angles, np.bincount(inverse, values) / counts, period=360.0)
        for name, values in sweep.columns.items()
    }
    columns.update({name: np.full(len(grid), sweep.columns[name][0]) for name in LABELS if sweep.has(name)})
    columns["theta0_deg"] = grid
    return fit.model.predict(dataclasses.replace(sweep, columns=columns), fit.values)


def figure_polar(report: LabReport) -> str | None:
    """Fig. 4 style: |Δf(θ0)| measured and model over one sweep, with the model's field part
    (harmonic 1 in θ0) and gradient part (harmonic 2), from the model on a 1° grid."""
    fit = report.fit
    rows = _largest_sweep(fit.table)
    theta = fit.table.theta0_rad[rows]
    if len(np.unique(np.round(np.mod(theta, 2 * np.pi), 6))) < 5:
        return None
    f00 = fit.row_f00_hz[rows][0]
    grid_deg = np.arange(0.0, 361.0)
    curve = sweep_curve(fit, rows, grid_deg) - f00
    spectrum = np.fft.rfft(curve[:-1]) / 360.0
    grid = np.radians(grid_deg)
    parts = {k: 2 * np.real(spectrum[k] * np.exp(1j * k * grid)) for k in (1, 2)}
    figure = _pyplot().figure(figsize=(6, 6))
    axis = figure.add_subplot(projection="polar")
    axis.plot(theta, np.abs(fit.table.f_hz[rows] - f00) * 1e3, ".", color="k", label="|Δf| measured")
    axis.plot(grid, np.abs(curve) * 1e3, "-", color="tab:red", label=f"|Δf| {report.model}")
    axis.plot(grid, np.abs(parts[1]) * 1e3, ":", color="tab:purple", label="field part (1θ0)")
    axis.plot(grid, np.abs(parts[2]) * 1e3, ":", color="tab:blue", label="gradient part (2θ0)")
    several = len(np.unique(fit.table.sweep_ids)) > 1
    axis.set_title("|Δf| against θ0, mHz (cf. paper Fig. 4)" + (", largest sweep" if several else ""))
    axis.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), ncol=2, fontsize=8)
    return _png(figure)


def _residual_panel(axis: Axes, x: np.ndarray, fit: FitResult, label: str, color: str) -> None:
    """Residuals f − model (mHz) with their σ, and the data's ±σ band (median σ)."""
    sigma = fit.table.f_std_hz * 1e3
    axis.errorbar(
        x,
        fit.residual_hz * 1e3,
        sigma,
        fmt=".",
        ms=3,
        alpha=0.7,
        color=color,
        label=label,
        rasterized=len(x) > RASTER_ROWS,
    )
    band = float(np.median(sigma))
    axis.axhspan(-band, band, color="tab:green", alpha=0.15, label="±σ (median)")
    axis.axhline(0, color="k", lw=0.5)
    axis.set_ylabel("f − model (mHz)")
    axis.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)


def figure_residuals(report: LabReport, x: np.ndarray, xlabel: str) -> str:
    """Residuals against ``x`` on separate axes, each on its own scale (the base model's are
    often 50× the final model's): the base model (Eq. 6), the final model, both in mHz with the
    data's ±σ band, and the final model's pulls (f − model)/σ with ±1 and ±3. Legends sit to
    the right of the axes, outside the data."""
    fits = [(report.base, "base (Eq. 6)", "tab:gray")]
    if report.effects:
        fits.append((report.fit, "final model", "tab:red"))
    figure, axes = _pyplot().subplots(
        len(fits) + 1, 1, figsize=(7.5, 2.2 * (len(fits) + 1)), sharex=True, constrained_layout=True
    )
    for axis, (fit, label, color) in zip(axes, fits):
        _residual_panel(axis, x, fit, label, color)
    pulls = axes[-1]
    pulls.plot(
        x,
        report.fit.weighted_residual,
        ".",
        ms=3,
        color=fits[-1][2],
        label=f"pulls, {fits[-1][1]}",
        rasterized=len(x) > RASTER_ROWS,
    )
    axes[0].set_title(f"final model: {report.model}" if report.effects else "", fontsize=8, loc="left")
    for level, style in ((1, "-"), (3, "--")):
        pulls.axhline(level, color="tab:green", ls=style, lw=0.8)
        pulls.axhline(-level, color="tab:green", ls=style, lw=0.8)
    pulls.axhline(0, color="k", lw=0.5)
    pulls.set(xlabel=xlabel, ylabel="(f − model)/σ")
    pulls.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
    for axis in axes:
        axis.label_outer()
    return _svg(figure)


def named_covariates(report: LabReport) -> list[str]:
    """The covariates the diagnosis names, in the table's order: those the residual follows
    significantly (:class:`mows.lab.diagnosis.residual_structure.Structure`) and the factors of
    the terms found beyond the catalog."""
    structure = report.diagnosis.structure
    named = {c.name for c in structure.covariates if c.p_value < structure.alpha}
    named |= {factor for term in (report.discovery.terms if report.discovery else []) for factor in term.factors}
    return [name for name in report.fit.table.covariates() if name in named]


def figure_term(term: DiscoveredTerm) -> str:
    """A term found beyond the catalog: the residual it explains against the term beyond what the
    model absorbs (:class:`mows.lab.diagnosis.discovery.TermFit`), with its fitted strength ± σ."""
    fitted = term.fitted
    assert fitted is not None
    figure, axis = _pyplot().subplots(figsize=(6.5, 3.5))
    many = len(fitted.beyond_model) > RASTER_ROWS
    axis.errorbar(
        fitted.beyond_model, fitted.residual_hz * 1e3, fitted.std_hz * 1e3, fmt=".", ms=3, alpha=0.7,
        color="k", label="residual it explains", rasterized=many,
    )  # fmt: skip
    x = np.linspace(np.min(fitted.beyond_model), np.max(fitted.beyond_model), 50)
    axis.plot(x, term.strength * x * 1e3, "-", color="tab:red", label=f"{term.strength:+.4g} {term.strength_unit}")
    band = np.abs(term.std * x) * 1e3
    axis.fill_between(x, (term.strength * x) * 1e3 - band, (term.strength * x) * 1e3 + band, color="tab:red", alpha=0.2)
    axis.set(xlabel=f"{term.name} beyond the model (Hz per {term.strength_unit})", ylabel="f − model (mHz)")
    axis.set_title(f"{term.name}: {term.family}", fontsize=9, loc="left")
    axis.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
    return _svg(figure)


def figure_candidates(report: LabReport) -> str | None:
    candidates = report.candidates
    if not candidates:
        return None
    figure, axis = _pyplot().subplots(figsize=(6, 0.35 * len(candidates) + 1))
    values = [c.delta_bic for c in candidates]
    colors = ["tab:red" if c.strong else "tab:gray" for c in candidates]
    axis.barh([c.label + (f" [group {c.group}]" if c.group else "") for c in candidates], values, color=colors)
    axis.axvline(10, color="k", ls="--", lw=0.8)
    axis.set_xscale("symlog", linthresh=10)
    axis.invert_yaxis()
    axis.set(xlabel="ΔBIC (> 10: strong evidence)", title="Candidate effects")
    return _png(figure)


def figure_history(report: LabReport) -> str:
    steps = report.history
    labels = [str(i) for i in range(len(steps))]  # the steps' changes are in the table below
    figure, (left, right) = _pyplot().subplots(1, 2, figsize=(8, 3))
    left.plot(labels, [s.chi2_dof for s in steps], "o-")
    left.set(yscale="log", ylabel="χ²/dof", title="fit")
    right.plot(labels, [s.cv_rms_hz * 1e3 for s in steps], "o-", color="tab:orange")
    right.set(ylabel="CV rms (mHz)", title="sweeps held out")
    for axis in (left, right):
        axis.set(xlabel="step")
    return _png(figure)


def _img(source: str | None, alt: str) -> str:
    return f'<img src="{source}" alt="{html.escape(alt)}">' if source else ""


def _figure(svg: str, kind: str, name: str, caption: str) -> str:
    """An inline SVG plot, marked with what it shows (``data-covariate``, ``data-term``)."""
    return (
        f'<figure class="{kind}" data-{kind}="{html.escape(name)}">{svg}'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


def _rows(cells_list: Iterable[Sequence[object]]) -> str:
    return "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells) + "</tr>" for cells in cells_list)


def discovery_html(report: LabReport) -> str:
    """The search beyond the catalog: its summary, a table of the terms, the strongest's plugin."""
    found = report.discovery
    if found is None:
        return ""
    rows = _rows(
        [
            (
                t.name,
                t.family,
                f"{t.strength:+.4g} ± {t.std:.2g} {t.strength_unit}",
                f"{100 * t.selection_frequency:.0f}%",
                f"{t.cv_gain_chi2:.1f}",
                t.reading,
                t.plugin_parameter.text() if t.plugin_parameter else "",
            )
            for t in found.terms
        ]
    )
    table = (
        "<table><tr><th>term</th><th>family</th><th>strength</th><th>selected</th><th>held-out χ² gain</th>"
        f"<th>reading</th><th>plugin parameter</th></tr>{rows}</table>"
        if found.terms
        else ""
    )
    fits = "".join(
        _figure(figure_term(t), "term", t.name, f"the residual {t.name} explains, and its fit")
        for t in found.terms
        if t.fitted is not None
    )
    plugin = (
        f"<p>Plugin for the strongest, <code>{html.escape(found.terms[0].effect_name)}.py</code>:</p>"
        f"<pre>{html.escape(found.terms[0].plugin)}</pre>"
        if found.terms
        else ""
    )
    return (
        f"<h2>Beyond the catalog</h2><p>On {html.escape(found.on_model)}: {html.escape(found.summary)}</p>"
        f"{table}{fits}{plugin}"
    )


def render_html(report: LabReport) -> str:
    """The report page as a string."""
    table = report.fit.table
    covariates = table.covariates()
    named = named_covariates(report)
    residual_plots = [
        _figure(figure_residuals(report, np.degrees(table.theta0_rad), "θ0 (deg)"), "covariate", "θ0", "residual vs θ0")
    ]
    residual_plots += [
        _figure(
            figure_residuals(report, covariates[name], name),
            "covariate",
            name,
            f"residual vs {name}" + (" (named by the diagnosis)" if name in named else ""),
        )
        for name in named + [name for name in covariates if name not in named]
    ]
    named_line = f"<p>The diagnosis names {html.escape(', '.join(named))}: plotted first.</p>" if named else ""
    candidates = _rows(
        [
            (
                i + 1,
                c.label,
                f"{c.delta_bic:.1f}",
                f"{c.p_value:.2g}",
                f"{c.chi2_dof_after:.3f}",
                c.group or "",
                "; ".join(p.text() for p in c.parameters),
            )
            for i, c in enumerate(report.candidates)
        ]
    )
    history = _rows(
        [
            (i, s.change, " + ".join(["eq6"] + s.effects), f"{s.chi2_dof:.3f}", f"{s.bic:.1f}", s.cv_text)
            for i, s in enumerate(report.history)
        ]
    )
    checks = _rows(
        [
            (
                c.effect,
                "held at physics" if c.held else "free",
                "; ".join(p.text() for p in c.parameters),
                f"{c.deviation_sigma:.1f}",
            )
            for c in report.physics_checks
        ]
    )
    groups = "".join(
        f"<li>group {g.number}: {html.escape(', '.join(g.members))} — {html.escape(g.separation)}"
        + "".join(f"<br>alias: {html.escape(a)}" for a in g.aliases)
        + "".join(f"<br>check {html.escape(c)}" for c in g.checks)
        + "</li>"
        for g in report.groups
    )
    parameters = _rows([(p.name, f"{p.value:.6g}", f"{p.std:.2g}", p.unit) for p in report.fit.parameters()])
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>MOWS model lab: {html.escape(table.source)}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto}} td{{padding:2px 8px}}
table{{border-collapse:collapse}} tr:nth-child(even){{background:#f2f2f2}}
img,svg{{max-width:100%;height:auto}}</style></head>
<body><h1>MOWS model lab</h1>
<p>Table <code>{html.escape(table.source)}</code>: {report.n} rows. Base model (Eq. 6, f00 fitted):
χ²/dof = {report.base.chi2_dof:.3f}. Final model <b>{html.escape(report.model)}</b>: χ²/dof = {report.chi2_dof:.3f}.</p>
<h2>Verdict: {html.escape(report.verdict)}</h2><p>{html.escape(report.diagnosis.explanation)}</p>
<h2>Model against measurement</h2>{_img(figure_field_response(report), "Fig. 3 style")}
{_img(figure_polar(report), "Fig. 4 style")}
<h2>Fitted parameters</h2><table><tr><th>parameter</th><th>value</th><th>σ</th><th>unit</th></tr>{parameters}</table>
<p>Effects with a physical value: their free fit with the rest of the model against it:</p>
<table><tr><th>effect</th><th>in the model</th><th>free fit</th><th>physical value off by (σ)</th></tr>
{checks}</table>
<h2>Residuals</h2><p>{html.escape(report.structure)}</p>{named_line}{"".join(residual_plots)}
<h2>Candidate effects</h2>{_img(figure_candidates(report), "candidates")}
<table><tr><th>rank</th><th>effect</th><th>ΔBIC</th><th>p</th><th>χ²/dof after</th><th>group</th>
<th>parameters (free fit)</th></tr>{candidates}</table><ul>{groups}</ul>
{discovery_html(report)}
<h2>Error history</h2>{_img(figure_history(report), "history")}
<table><tr><th>step</th><th>change</th><th>model</th><th>χ²/dof</th><th>BIC</th><th>CV rms (mHz)</th></tr>
{history}</table>
<p>Notes: {html.escape("; ".join(report.notes) or "none")}</p></body></html>"""


def write_html(report: LabReport, path: str | os.PathLike[str]) -> pathlib.Path:
    """Write the report page to ``path``."""
    path = pathlib.Path(path)
    path.write_text(render_html(report))
    return path
