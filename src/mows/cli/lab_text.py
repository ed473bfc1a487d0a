"""``mows lab``'s text output: the report of compare | diagnose | add as the terminal shows it
(``--json`` prints the same report machine-readable; :mod:`mows.cli.lab`)."""

import math


def format_text(report, table, command: str) -> str:
    lines = [f"table: {table.source}: {report.n} rows, {len(set(table.sweep_ids))} sweep(s)"]
    lines += [f"  note: {note}" for note in report.notes]
    lines.append(f"base model (eq6, f00 fitted): χ²/dof = {report.base.chi2_dof:.3f}")
    lines.append("")
    lines.append(report.fit.report())
    lines.append("")
    lines.append(_structure_text(report.diagnosis.structure))
    if command != "compare":
        lines += ["", _candidates_text(report)]
    if len(report.history) > 1 or command == "add":
        lines += ["", _history_text(report.history)]
    if report.physics_checks:
        lines += ["", _checks_text(report.physics_checks)]
    if report.discovery is not None:
        lines += ["", *report.discovery.lines()]
    lines += ["", f"verdict: {report.verdict}", "  " + report.diagnosis.explanation]
    return "\n".join(lines)


def _structure_text(structure) -> str:
    lines = ["residual structure (after what the model absorbs):", "  harmonic   amplitude (mHz)   phase (deg)   p"]
    for h in structure.harmonics:
        lines.append(
            f"  {h.k:8d}   {h.text()}" + ("" if h.absorbed else f", p = {h.p_value:.2g}")
            if h.absorbed or not h.identifiable
            else f"  {h.k:8d}   {h.amplitude_hz * 1e3:8.3f} ± {h.std_hz * 1e3:6.3f}   "
            f"{math.degrees(h.phase_rad):8.1f}   {h.p_value:.2g}"
        )
    if structure.covariates:
        lines.append("  covariate            correlation   slope            p")
        for c in structure.covariates:
            lines.append(f"  {c.name:20s} {c.correlation:+8.3f}     {c.slope:+.3e}   {c.p_value:.2g}")
    lines.append(f"  significance level per test (Bonferroni): {structure.alpha:.1e}")
    lines.append("  " + structure.summary)
    return "\n".join(lines)


def _candidates_text(report) -> str:
    lines = [
        "candidate effects, best first, each in its better form by BIC (ΔBIC > 10 is strong evidence;",
        "'at physics': held at its physical value, no free parameter; parameters: the free fit):",
        "  rank effect                  form          ΔBIC        p         χ²/dof after  group  parameters",
    ]
    for rank, c in enumerate(report.candidates, 1):
        values = ", ".join(p.text() for p in c.parameters)
        lines.append(
            f"  {rank:4d} {c.name:22s}  {c.form:10s} {c.delta_bic:9.1f}   {c.p_value:9.2g}   "
            f"{c.chi2_dof_after:10.3f}   {c.group or '-':>4}   {values}"
        )
        if c.would_need:
            lines.append(f"         not physics: {c.would_need}")
    for group in report.groups:
        lines.append(
            f"  group {group.number}: {group.separation}"
            if group.in_model
            else f"  group {group.number}: {', '.join(group.members)} cannot be told apart by this data; "
            f"{group.separation}"
        )
        lines += [f"    alias: {alias}" for alias in group.aliases]
        lines += [f"    check {check}" for check in group.checks]
    for name, reason in report.untestable.items():
        lines.append(f"  not tested: {name}: {reason}")
    return "\n".join(lines)


def _history_text(history) -> str:
    lines = ["error history:", "  step  χ²/dof      BIC        CV rms (mHz)  change → model"]
    for i, step in enumerate(history):
        name = " + ".join(["eq6"] + step.effects)
        lines.append(f"  {i:4d}  {step.chi2_dof:9.3f}  {step.bic:10.1f}  {step.cv_text:>10}    {step.change} → {name}")
        lines += [f"          free fit: {p.text()}" for p in step.check]
    return "\n".join(lines)


def _checks_text(checks) -> str:
    lines = ["effects with a physical value, their free fit with the rest of the model against it:"]
    for check in checks:
        values = ", ".join(p.text() for p in check.parameters)
        form = "held at physics" if check.held else "free"
        lines.append(f"  {check.effect} ({form}): {values} (physical value {check.deviation_sigma:.1f}σ away)")
    return "\n".join(lines)
