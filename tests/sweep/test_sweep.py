"""Rotation-sweep decomposition against exact fields of real sources."""

import math

import numpy as np
import pytest

from mows.physics.field import UniformField, anti_helmholtz_pair
from mows.physics.frequency import PublishedSweep
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.decompose import decompose, unknown_count
from mows.sweep.decomposition import DecompositionStatus, fit_harmonics

THETA0 = np.radians(np.arange(0.0, 360.0, 15.0))
STD_HZ = 3e-4


def exact_sweep(source, seed):
    """Δf at each θ0 from the full potential in the source's actual field, plus noise."""
    f = np.array([ArcPotential.from_source(P, source, Pose(theta0_rad=t)).frequency_hz() for t in THETA0])
    return f - P.f00_hz + STD_HZ * np.random.default_rng(seed).standard_normal(THETA0.size)


@pytest.fixture(scope="module")
def gradient_field():
    return anti_helmholtz_pair((0, 0, 0), (1, 0, 0), 0.105, 200, 0.5) + UniformField((20e-6, -12e-6, -40e-6))


def truth(source):
    b, g = source.field_t(np.zeros(3)), source.gradient_t_per_m(np.zeros(3))
    return b[:2], np.array([g[0, 0], g[0, 1], g[1, 1]])


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_first_principles_recovers_field_and_gradient(gradient_field, seed):
    d = decompose(THETA0, exact_sweep(gradient_field, seed), np.full(THETA0.size, STD_HZ), P, P.f00_hz)
    b, g = truth(gradient_field)
    assert d.ok and d.chi2_dof < 2.0
    assert np.all(np.abs(d.field_t - b) < 4 * np.sqrt(np.diag(d.field_covariance_t2)))
    assert np.all(np.abs(d.gradient_t_per_m - g) < 4 * np.sqrt(np.diag(d.gradient_covariance)))


def test_published_model_overstates_an_axial_gradient_two_and_fivefold(gradient_field):
    # docs/physics.md §6.1: the lever also feels Gy'y'; for an axisymmetric gradient along x the
    # published model must read Gxx twice and Gyy five times too large (cf. the paper's
    # measured γ = 14.14 Hz·m/T against γ0 = β0·l = 7.16 Hz·m/T).
    shift = exact_sweep(gradient_field, 4)
    published = decompose(THETA0, shift, np.full(THETA0.size, STD_HZ), P, P.f00_hz, model="published")
    exact = decompose(THETA0, shift, np.full(THETA0.size, STD_HZ), P, P.f00_hz)
    _, g = truth(gradient_field)
    assert published.gradient_t_per_m[0] / g[0] == pytest.approx(2.0, rel=0.02)
    assert published.gradient_t_per_m[2] / g[2] == pytest.approx(5.0, rel=0.02)
    assert published.chi2_dof > exact.chi2_dof


def test_published_model_inverts_its_own_sweep():
    field, gradient = (35e-6, -8e-6), (2e-3, 1.5e-3, -4e-3)
    shift = PublishedSweep(field, gradient, P.f00_hz, P.spring_nm_per_rad, P.moment_am2, P.lever_m).shift_hz(THETA0)
    d = decompose(THETA0, shift, np.full(THETA0.size, STD_HZ), P, P.f00_hz, model="published")
    np.testing.assert_allclose(d.field_t, field, rtol=1e-6)
    np.testing.assert_allclose(d.gradient_t_per_m, gradient, rtol=1e-5, atol=1e-9)


def test_harmonics_follow_eq12_for_a_uniform_field():
    b = np.array([30e-6, 17e-6])
    d = decompose(THETA0, exact_sweep(UniformField((*b, 0.0)), 5), np.full(THETA0.size, STD_HZ), P, P.f00_hz)
    h = d.harmonics
    assert h.amplitude_hz[1] == pytest.approx(
        P.f00_hz * P.moment_am2 * np.hypot(*b) / (2 * P.spring_nm_per_rad), rel=0.01
    )
    assert h.phase_rad[1] == pytest.approx(-math.atan2(b[1], b[0]), abs=0.01)
    assert abs(h.amplitude_hz[2]) < 5 * STD_HZ / math.sqrt(THETA0.size / 2)


def test_free_f00_absorbs_the_constant_gradient_term(gradient_field):
    d = decompose(THETA0, exact_sweep(gradient_field, 6), np.full(THETA0.size, STD_HZ), P, P.f00_hz, f00_free=True)
    _, g = truth(gradient_field)
    assert d.ok and d.f00_free
    assert np.isnan(d.gradient_t_per_m[[0, 2]]).all()
    assert abs(d.gradient_t_per_m[1] - g[1]) < 4 * math.sqrt(d.gradient_covariance[1, 1])
    # The constant first-principles term −f00·l·m·Gs/(2kM) moved into f00.
    gs = 0.5 * (g[0] + g[2])
    assert d.f00_hz - P.f00_hz == pytest.approx(-P.gamma0_hz_m_per_t * gs, rel=0.05)


@pytest.mark.parametrize(
    "theta0, shift, std, words",
    [
        (THETA0[:4], np.zeros(4), np.full(4, STD_HZ), "distinct orientations"),
        (THETA0, np.full(THETA0.size, np.nan), np.full(THETA0.size, STD_HZ), "non-finite"),
        (THETA0, np.zeros(THETA0.size), np.zeros(THETA0.size), "positive"),
    ],
)
def test_unusable_sweeps_are_refused_with_a_reason(theta0, shift, std, words):
    d = decompose(theta0, shift, std, P, P.f00_hz)
    assert not d.ok and words in d.message
    assert np.isnan(d.field_t).all()


def test_unknown_model_is_an_error():
    with pytest.raises(ValueError, match="published"):
        decompose(THETA0, np.zeros(THETA0.size), np.full(THETA0.size, STD_HZ), P, P.f00_hz, model="paper")


def test_fit_harmonics_reproduces_a_known_series():
    shift = 1e-3 + 2e-3 * np.cos(THETA0 + 0.3) + 5e-4 * np.cos(2 * THETA0 - 1.0)
    h = fit_harmonics(THETA0, shift, np.full(THETA0.size, 1e-4))
    np.testing.assert_allclose(h.amplitude_hz, [1e-3, 2e-3, 5e-4], atol=1e-12)
    np.testing.assert_allclose(h.phase_rad[1:], [0.3, -1.0], atol=1e-9)


@pytest.mark.parametrize("f00_free", [False, True])
def test_a_sweep_needs_one_distinct_orientation_per_unknown(f00_free):
    # Eq. 12 up to 2θ0 has five coefficients (constant, cos θ0, sin θ0, cos 2θ0, sin 2θ0): at
    # fewer distinct orientations than that its design matrix loses rank; f00 free adds one.
    def rank(angles):
        return np.linalg.matrix_rank(
            np.column_stack([np.cos(k * angles) for k in (0, 1, 2)] + [np.sin(k * angles) for k in (1, 2)])
        )

    needed = unknown_count(f00_free)
    angles = np.radians(10.0 + 360.0 / needed * np.arange(needed))
    assert rank(angles[:5]) == 5 and rank(angles[:4]) == 4
    field, gradient = (35e-6, -8e-6), (2e-3, 1.5e-3, -4e-3)
    shift = PublishedSweep(field, gradient, P.f00_hz, P.spring_nm_per_rad, P.moment_am2, P.lever_m).shift_hz(angles)
    std = np.full(needed, STD_HZ)
    enough = decompose(angles, shift, std, P, P.f00_hz, model="published", f00_free=f00_free)
    assert enough.ok
    # With f00 free the constant gradient term is read as an f00 offset, which rescales the
    # field's harmonic by that offset over f00 (~1e-4 here).
    np.testing.assert_allclose(enough.field_t, field, rtol=1e-3 if f00_free else 1e-6)
    short = decompose(angles[1:], shift[1:], std[1:], P, P.f00_hz, model="published", f00_free=f00_free)
    assert short.status is DecompositionStatus.TOO_FEW_ORIENTATIONS
    assert f"need at least {needed}" in short.message


def test_a_sweep_with_as_many_orientations_as_coefficients_says_it_has_no_degrees_of_freedom():
    theta0 = np.radians(np.arange(0.0, 360.0, 72.0))  # 5 orientations, 5 free coefficients
    source = UniformField((20e-6, 5e-6, 0.0))
    f = np.array([ArcPotential.from_source(P, source, Pose(theta0_rad=t)).frequency_hz() for t in theta0])
    d = decompose(theta0, f - P.f00_hz, np.full(theta0.size, STD_HZ), P, P.f00_hz)
    assert d.ok and math.isnan(d.chi2_dof)
    assert "χ²/dof not determined (0 degrees of freedom" in d.report() and "nan" not in d.report()


def test_a_sweep_no_field_describes_is_refused_in_the_decomposition_s_words():
    """±50 Hz in cos θ0 about f00 = 112.5 Hz: the field spring adds to the mechanical one as
    f² ∝ k ± m·B, so f(0°)² + f(180°)² would be 2·f00² for any field along the probe; here it is
    20 % more. The linear start (Eq. 11) then lies beyond the potential's stable range: the
    decomposition says so (not scipy's "Residuals are not finite in the initial point")."""
    shift = 50.0 * np.cos(THETA0)
    d = decompose(THETA0, shift, np.full(THETA0.size, STD_HZ), P, P.f00_hz)
    assert d.status is DecompositionStatus.INVALID_INPUT
    assert "no finite frequency shift" in d.message
