"""A plugin's energy U_user(θ) goes through the same exact potential as the catalog.

Requirement: an effect written as the energy it adds to U(θ) (plugin output ``energy_j``) must
give the frequency of that potential, by the lab's rest angle and harmonic balance. Checked
against closed forms: an induced moment, U = −½·α·(u·B)², in a field B along the probe gives
k = kM + m·B + α·B² (the curvature of −½·α·B²·cos²θ at 0 is α·B²); a stiffening hinge,
U = ¼·k3·θ⁴, leaves the small-swing frequency alone and at amplitude A adds ¾·k3·A² to the
first-harmonic stiffness (Duffing); and an extra moment written as energy, −c·m·u·B, is the
catalog's moment scale c exactly.
"""

import math

import numpy as np
import pytest

from mows.lab import FrequencyModel, MeasurementTable, ProbeSet, catalog, effect
from mows.lab.model.configuration import Configuration, LeverArc
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE


@effect(name="induced_moment", parameters={"alpha_am2_per_t": (0.0, -10.0, 10.0, "A·m²/T")})
def induced_moment(rows, alpha_am2_per_t):
    return {"energy_j": lambda arc: -0.5 * alpha_am2_per_t * (arc.field_t * arc.direction).sum(-1) ** 2}


@effect(name="hinge", parameters={"k3_nm_per_rad3": (0.0, -1.0, 1.0, "N·m/rad³")})
def hinge(rows, k3_nm_per_rad3):
    return {"energy_j": lambda arc: 0.25 * k3_nm_per_rad3 * arc.theta_rad**4}


@effect(name="extra_moment", parameters={"c": (0.0, -1.0, 1.0, "1")})
def extra_moment(rows, c):
    return {"energy_j": lambda arc: -c * arc.moment_am2 * (arc.field_t * arc.direction).sum(-1)}


def _table(field_along_t, amplitude_deg=None):
    b = np.atleast_1d(np.asarray(field_along_t, float))
    columns = {"theta0_deg": np.zeros(len(b)), "f_hz": np.full(len(b), 100.0), "f_std_hz": np.full(len(b), 1e-3)}
    columns["ref_bx_t"], columns["ref_by_t"] = b, np.zeros(len(b))
    if amplitude_deg is not None:
        columns["amplitude_deg"] = np.full(len(b), amplitude_deg)
    return MeasurementTable(columns, "closed form")


def test_an_induced_moment_adds_alpha_b_squared_to_the_stiffness():
    field_t = np.array([-2e-3, -5e-4, 5e-4, 1e-3, 2e-3])
    alpha = 2e-3  # A·m²/T: at 2 mT, 4e-9 N·m against kM = 1.4e-5
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE)) + induced_moment
    found = model.predict(_table(field_t), [PAPER_PROBE.f00_hz, alpha])
    kM, m = PAPER_PROBE.spring_nm_per_rad, PAPER_PROBE.moment_am2
    expected = PAPER_PROBE.f00_hz * np.sqrt(1.0 + (m * field_t + alpha * field_t**2) / kM)
    np.testing.assert_allclose(found, expected, rtol=1e-11)
    without = FrequencyModel(ProbeSet.one(PAPER_PROBE)).predict(_table(field_t), [PAPER_PROBE.f00_hz])
    assert np.all(np.abs(found - without) > 1e-4)  # the term is there, 0.1–1 mHz and more


def test_an_energy_written_moment_is_the_catalog_moment_scale():
    table = _table([3e-4, -8e-4, 1.5e-3])
    c = 0.03
    energy = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + extra_moment).predict(table, [PAPER_PROBE.f00_hz, c])
    scaled = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + catalog()["moment_scale"]).predict(
        table, [PAPER_PROBE.f00_hz, c]
    )
    np.testing.assert_allclose(energy, scaled, rtol=1e-12)


@pytest.mark.parametrize("amplitude_deg", [8.0, 16.0])
def test_a_stiffening_hinge_is_a_duffing_spring_at_finite_amplitude(amplitude_deg):
    """In zero field the amplitude readout averages over the ring-down; a constant-amplitude
    check uses the first-harmonic stiffness kM + ¾·k3·A² directly on the lab's potential."""
    k3 = 1e-5  # N·m/rad³: ¾·k3·A² is 0.5 % of kM at 8°
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE)) + hinge
    table = _table([0.0], amplitude_deg)
    small = model.predict(table, [PAPER_PROBE.f00_hz, k3])
    np.testing.assert_allclose(small, PAPER_PROBE.f00_hz, rtol=1e-12)  # U''(0) has no θ⁴ term
    config = Configuration.base(table, PAPER_PROBE)
    arc = LeverArc.of(config, PAPER_PROBE)
    potential = ArcPotential.from_local_field(
        PAPER_PROBE, np.zeros((1, 3)), energy_j=0.25 * k3 * arc.theta_rad[None] ** 4
    )
    amplitude = math.radians(amplitude_deg)
    k_first_harmonic = float(potential.effective_stiffness_nm_per_rad(amplitude)[0])
    # The Duffing first harmonic: kM + ¾·k3·A² (+ O(A⁴) from the cycle's higher harmonics, none
    # here: the potential is even about 0, so A2 = 0 and the balance is exact first-harmonic).
    expected = PAPER_PROBE.spring_nm_per_rad + 0.75 * k3 * amplitude**2
    assert k_first_harmonic == pytest.approx(expected, rel=1e-10)
