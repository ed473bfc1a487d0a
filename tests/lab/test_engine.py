"""The lab's physics engine: Eq. 6 exactly with no effect, the exact potential with effects,
every effect off at 0, and the ring-down averaging checked against the estimator itself."""

import math

import numpy as np
import pytest

from mows.estimate.ringdown import fit_ringdown
from mows.lab import FrequencyModel, MeasurementTable, ProbeSet, catalog
from mows.lab.data.synthetic import true_frequency_hz
from mows.lab.data.table import NEIGHBOUR
from mows.physics import frequency, ringdown_average
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE


def random_table(rng, n=40, field_scale=2e-3, gradient_scale=0.05, **extra):
    columns = {"theta0_deg": rng.uniform(0, 360, n), "f_hz": np.full(n, 112.0), "f_std_hz": np.full(n, 1e-3)}
    for name in ("ref_bx_t", "ref_by_t", "ref_bz_t"):
        columns[name] = rng.normal(0, field_scale, n)
    for name in ("ref_gxx_t_per_m", "ref_gxy_t_per_m", "ref_gyy_t_per_m"):
        columns[name] = rng.normal(0, gradient_scale, n)
    columns.update(extra)
    return MeasurementTable(columns)


def test_the_base_model_is_eq6_exactly_up_to_mT_fields():
    table = random_table(np.random.default_rng(1))
    h, c = FrequencyModel(ProbeSet.one(PAPER_PROBE)).factors(table, [])
    probe = PAPER_PROBE
    axes = table.probe_axes()
    along = np.einsum("ni,ni->n", axes[:, 0], table.field_t)
    gradient = np.einsum("ni,nij,nj->n", axes[:, 0], table.gradient_t_per_m, axes[:, 0])
    field_spring = frequency.field_spring_nm_per_rad(probe.moment_am2, along) + frequency.gradient_spring_nm_per_rad(
        probe.moment_am2, probe.lever_m, gradient
    )
    shift = frequency.frequency_shift_hz(probe.f00_hz, probe.spring_nm_per_rad, field_spring)
    np.testing.assert_allclose(probe.f00_hz * h + c, probe.f00_hz + shift, rtol=1e-12)


def test_with_all_field_effects_the_engine_is_the_exact_potential_in_a_uniform_field():
    field = (1.2e-3, -0.8e-3, 0.3e-3)
    theta0 = np.radians(np.arange(0, 360, 30.0))
    n = len(theta0)
    table = MeasurementTable(
        {
            "theta0_deg": np.degrees(theta0),
            "f_hz": np.full(n, 112.0),
            "f_std_hz": np.full(n, 1e-3),
            **dict(zip(("ref_bx_t", "ref_by_t", "ref_bz_t"), np.repeat(np.array(field)[:, None], n, 1))),
        }
    )
    effects = catalog()
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["static_deflection"] + effects["damping_shift"]
    exact = true_frequency_hz(PAPER_PROBE, UniformField(field), theta0, 1e-12)
    # Static deflection at 1.4 mT is ~0.4 Hz; the lab and the independent source evaluation agree.
    np.testing.assert_allclose(model.predict(table, [PAPER_PROBE.f00_hz, 1.0, 1.0]), exact, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(catalog()))
def test_every_effect_is_off_at_zero(name):
    rng = np.random.default_rng(2)
    table = random_table(
        rng,
        field_scale=1e-4,
        gradient_scale=0.01,
        temperature_k=rng.uniform(290, 300, 40),
        t_s=np.arange(40.0),
        amplitude_deg=np.full(40, 20.0),
        damping_per_s=np.full(40, 2.5),
        **dict(zip(NEIGHBOUR, np.full((len(NEIGHBOUR), 40), 1e-5))),  # what mutual_coupling reads
    )
    effect = catalog()[name]
    base = FrequencyModel(ProbeSet.one(PAPER_PROBE)).predict(table, [112.48])
    with_effect = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effect).predict(
        table, [112.48] + [0.0] * len(effect.parameters)
    )
    np.testing.assert_allclose(with_effect, base, rtol=0, atol=1e-12)


def chirped_ringdown(
    theta0,
    frequency_of_amplitude,
    amplitude0=math.radians(24.0),
    damping=1.8,
    fs=20000.0,
    seconds=0.5,
    noise_t=1e-9,
    kappa_t=1e-6,
):
    t = np.arange(int(seconds * fs)) / fs
    amplitude = amplitude0 * np.exp(-damping * t)
    phase = 2 * np.pi * np.cumsum(frequency_of_amplitude(amplitude)) / fs + 0.3
    signal = -kappa_t * np.sin(theta0 + amplitude * np.cos(phase))
    return signal + np.random.default_rng(1).normal(0, noise_t, t.size), fs


@pytest.mark.parametrize("theta0_deg", [0.0, 50.0, 90.0])
def test_the_ringdown_average_is_what_the_estimator_reports(theta0_deg):
    theta0 = math.radians(theta0_deg)

    def law(amplitude):  # a frequency falling with amplitude, like the field term's 2·J1(A)/A
        return 112.0 * (1.0 - 2e-3 * amplitude**2)

    signal, fs = chirped_ringdown(theta0, law)
    fit = fit_ringdown(signal, fs, theta0, 112.0)
    assert fit.ok
    start = math.radians(24.0)  # the simulated ring-down's start swing (θmax need not be determined)
    amplitudes, weights = ringdown_average.amplitude_nodes(theta0, start, fit.damping_per_s, 0.5)
    predicted = float((weights * law(amplitudes)).sum())
    at_start = law(start)
    assert abs(fit.frequency_hz - predicted) < 2.5 * fit.frequency_std_hz
    assert abs(fit.frequency_hz - at_start) > 10 * fit.frequency_std_hz  # the averaging matters
