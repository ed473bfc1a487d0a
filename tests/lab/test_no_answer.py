"""When no catalog effect explains the residual, the lab says so, names the terms the search beyond
the catalog finds (mows.lab.diagnosis.discovery) with the strongest one's plugin, and shows what the
residual follows (covariates and products of two)."""

import numpy as np

from mows.lab import ProbeSet, analyse
from mows.lab.data import synthetic
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE


def test_a_hidden_current_times_temperature_term_is_pointed_at():
    sweep = synthetic.rotation_sweeps(15.0, 4)
    theta0 = sweep.pop("theta0_deg")
    rng = np.random.default_rng(0)
    current = np.repeat([0.0, 1.0, 2.0, 3.0], 24)
    # About the probe's reference temperature, not a drift in time: uncorrelated with t_s.
    temperature = PAPER_PROBE.reference_temperature_k + rng.uniform(-1.0, 1.0, len(theta0))
    table = synthetic.synthesize(
        PAPER_PROBE,
        UniformField((2e-5, 0.0, 0.0)),
        theta0,
        rng,
        coil_current_a=current,
        temperature_k=temperature,
        **sweep,
    )
    # No catalog effect is a frequency term ∝ I·ΔT (4 mHz per A·K), ΔT from the probe's reference
    # temperature (where the discovery measures temperatures from).
    hidden = 0.004 * current * (temperature - PAPER_PROBE.reference_temperature_k)
    report = analyse(
        table.with_columns(f_hz=table.f_hz + hidden), ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False
    )
    assert report.verdict == "unexplained_structure"
    explanation = report.diagnosis.explanation
    assert "The residual follows temperature_k·coil_current_a (correlation +0.9" in explanation
    # The search beyond the catalog names the product in physical units, with its plugin.
    # A frequency change with no field pattern is the spring's: Δk = 2·kM·Δf/f00 per K·A.
    assert "finds 1 term: spring × temperature_k·coil_current_a" in explanation, explanation
    assert '@effect(name="discovered_spring_temperature_k_coil_current_a"' in explanation
    assert '"stiffness_nm_per_rad": k_nm_per_rad * (rows.temperature_k - 293.15) * rows.coil_current_a' in explanation
    (term,) = report.discovery.terms
    spring = 2.0 * PAPER_PROBE.spring_nm_per_rad * 0.004 / PAPER_PROBE.f00_hz
    assert abs(term.strength - spring) < 3 * term.std, (term.strength, term.std, spring)  # N·m/rad per K·A


def test_an_angle_pattern_that_changes_in_time_is_not_a_pile_of_catalog_effects():
    """A 3θ0 pattern whose sign flips over the run, 50 mHz·cos 3θ0·(t − t̄)/T, in a table with no
    catalog effect (2° ring-downs: no finite-amplitude readout): no catalog effect has it (the
    curvature's 3θ0 term is constant), the residual stays ≈ 100× its noise, and a raw-χ² BIC
    rewards parameters that shave a little off it (measured: gravity, then field curvature, BIC
    10225 → 10082 while χ²/dof rose 108 → 113). Judged against the residual's own scatter,
    nothing is added; the lab says so, points at the product and sketches the plugin."""
    sweep = synthetic.rotation_sweeps(15.0, 4)
    theta0 = sweep.pop("theta0_deg")
    t = sweep["t_s"]
    table = synthetic.synthesize(
        PAPER_PROBE, UniformField((2e-5, 5e-6, 0.0)), theta0, np.random.default_rng(1), amplitude_deg=2.0, **sweep
    )
    hidden = 0.05 * np.cos(3 * np.radians(theta0)) * t / np.ptp(t)  # t from the table's start
    report = analyse(
        table.with_columns(f_hz=table.f_hz + hidden), ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False
    )
    assert report.base.chi2_dof > 50, report.base.chi2_dof
    assert report.effects == [], report.history
    assert report.verdict == "unexplained_structure"
    explanation = report.diagnosis.explanation
    # field_curvature would take the 3θ0 share of the term: beside the discovered term it has no evidence
    assert "leaves structure that terms beyond the catalog explain" in explanation, explanation
    # No channel of the potential makes a 3θ0 pattern in a uniform field: the last resort, said so.
    assert "finds 1 term: frequency × t_s·cos(3θ0)" in explanation, explanation
    assert "c_hz * rows.t_s * np.cos(3 * rows.theta0_rad)" in explanation
    (term,) = report.discovery.terms
    assert term.plugin_output == "frequency_hz" and "no channel of the potential" in term.last_resort
    assert any("written as an additive frequency, the last resort" in line for line in report.discovery.lines())
    assert "Last resort: no channel of the potential" in " ".join(term.plugin.split())
    assert abs(term.strength - 0.05 / np.ptp(t)) < 3 * term.std, (term.strength, term.std)  # Hz per s
