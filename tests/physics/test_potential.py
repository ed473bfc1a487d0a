"""The first-principles potential against closed forms and an exact period integral."""

import math

import numpy as np
import pytest
from scipy import integrate, optimize, special

from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P

KM, M = P.spring_nm_per_rad, P.moment_am2


def along(b_t):
    return ArcPotential.from_local_field(P, np.array([b_t, 0.0, 0.0]))


@pytest.mark.parametrize("field_t", [1e-9, 50e-6, -3e-3, 5e-3, 40e-3])
def test_uniform_axial_field_gives_exactly_km_plus_mb(field_t):
    # U = ½kMθ² − mB·cos θ: θs = 0 and U''(0) = kM + mB with no approximation.
    assert along(field_t).stiffness_nm_per_rad() == pytest.approx(KM + M * field_t, rel=1e-12, abs=1e-20)


@pytest.mark.parametrize("amplitude_deg, factor", [(15.0, 0.991), (24.0, 0.978)])
def test_finite_amplitude_field_spring_follows_bessel_j1(amplitude_deg, factor):
    # docs/physics.md §6.3: first-harmonic stiffness of −mB cos θ is mB·2J1(A)/A.
    amplitude = math.radians(amplitude_deg)
    k = along(5e-3).effective_stiffness_nm_per_rad(amplitude)
    assert (k - KM) / (M * 5e-3) == pytest.approx(2 * special.j1(amplitude) / amplitude, rel=1e-10)
    assert 2 * special.j1(amplitude) / amplitude == pytest.approx(factor, abs=5e-4)


def test_amplitude_nodes_of_each_row_follow_bessel_j1():
    # Several amplitudes per batch element (a ring-down's nodes), in fields of either sign, each
    # against mB·2J1(A)/A; a zero amplitude is the rest stiffness kM + mB.
    fields = np.array([5e-3, -3e-3, 40e-3])
    amplitudes = np.radians([[0.0, 8.0, 15.0, 24.0], [3.0, 12.0, 20.0, 30.0], [1.0, 5.0, 10.0, 15.0]])
    potential = ArcPotential.from_local_field(P, np.stack([fields, 0 * fields, 0 * fields], -1))
    k = potential.effective_stiffness_nm_per_rad(amplitudes)
    safe = np.where(amplitudes > 0, amplitudes, 1.0)
    bessel = np.where(amplitudes > 0, 2 * special.j1(safe) / safe, 1.0)
    assert k.shape == amplitudes.shape
    np.testing.assert_allclose((k - KM) / (M * fields[:, None]), bessel, rtol=1e-10)


def exact_period_s(field_t, amplitude):
    """Period of the undamped swing from energy conservation, T = 4∫dθ/θ'."""

    def u(theta):
        return 0.5 * KM * theta**2 - M * field_t * math.cos(theta)

    # θ = A sin s removes the end-point singularity.
    def integrand(s):
        return amplitude * math.cos(s) / math.sqrt(2 * (u(amplitude) - u(amplitude * math.sin(s))) / P.inertia_kgm2)

    return 4 * integrate.quad(integrand, 0, math.pi / 2, epsabs=0, epsrel=1e-13, limit=200)[0]


@pytest.mark.parametrize("field_t", [5e-3, -5e-3])
def test_harmonic_balance_frequency_is_within_0p1_mhz_of_the_exact_period(field_t):
    undamped = P.replace(damping_per_s=0.0)
    potential = ArcPotential.from_local_field(undamped, np.array([field_t, 0.0, 0.0]))
    amplitude = math.radians(15.0)
    exact_hz = 1 / exact_period_s(field_t, amplitude)
    assert abs(potential.frequency_hz(amplitude) - exact_hz) < 1e-4
    # ...while the amplitude effect itself is far larger than that.
    assert abs(potential.frequency_hz(0.0) - exact_hz) > 0.05


def test_perpendicular_field_turns_the_rest_angle_and_stiffens_the_spring():
    # U = ½kMθ² − m·B⊥·sin θ; solve U' = 0 independently and take U'' there.
    b_perp = 170e-6
    theta_s = optimize.brentq(lambda t: KM * t - M * b_perp * math.cos(t), -0.5, 0.5, xtol=1e-16)
    potential = ArcPotential.from_local_field(P, np.array([0.0, b_perp, 0.0]))
    assert potential.rest_angle_rad() == pytest.approx(theta_s, rel=1e-10)
    assert potential.stiffness_nm_per_rad() == pytest.approx(KM + M * b_perp * math.sin(theta_s), rel=1e-12)
    # docs/physics.md §6.2: about 7 mHz at 170 µT.
    assert (potential.frequency_hz() - P.f00_hz) * 1e3 == pytest.approx(7.0, abs=0.1)


def test_the_rest_angle_is_the_cycle_centre_of_a_vanishing_swing_and_nan_where_unstable():
    # One Newton solves both: at rest the balance is U'(θs) = 0 on one point, in a swing it is
    # averaged over the cycle. Rows: perpendicular fields (θs from brentq as above), and an
    # axial field beyond spring cancellation (no stable rest angle).
    b_perp = np.array([170e-6, -2e-3, 0.0])
    fields = np.array([[0.0, b, 0.0] for b in b_perp] + [[1.01 * P.cancellation_field_t, 0.0, 0.0]])
    potential = ArcPotential.from_local_field(P, fields)
    rest = potential.rest_angle_rad()
    for b, theta in zip(b_perp, rest):
        expected = optimize.brentq(lambda t, b=b: KM * t - M * b * math.cos(t), -0.5, 0.5, xtol=1e-16)
        assert theta == pytest.approx(expected, rel=1e-10, abs=1e-15)
    assert np.isnan(rest[-1])
    tiny_swing = potential.cycle_centre_rad(np.full(len(fields), 1e-6))
    np.testing.assert_allclose(tiny_swing[:-1], rest[:-1], rtol=1e-9, atol=1e-15)
    assert np.isnan(tiny_swing[-1])


def test_where_the_probe_settles_is_the_minimum_of_u_it_falls_into_from_zero():
    # Rows: a perpendicular field (a stable rest: the rest angle itself); 3 % past cancellation
    # along the axis with a field across pushing either way (lopsided double wells: it falls to
    # the side the field across pushes it); and past cancellation so far that U falls beyond
    # the interval (±0.75 rad: no rest inside it). U = ½kM·θ² − m·(Bx·cos θ + By·sin θ).
    cancel = P.cancellation_field_t
    fields = np.array(
        [[0.0, 170e-6, 0.0], [1.03 * cancel, 50e-6, 0.0], [1.03 * cancel, -50e-6, 0.0], [3 * cancel, 0, 0]]
    )
    potential = ArcPotential.from_local_field(P, fields)
    settled = potential.settled_angle_rad()
    assert settled[0] == potential.rest_angle_rad()[0]
    for row, bounds in ((1, (1e-3, 0.7)), (2, (-0.7, -1e-3))):
        bx, by = fields[row, :2]
        well = optimize.minimize_scalar(
            lambda t, bx=bx, by=by: 0.5 * KM * t**2 - M * (bx * math.cos(t) + by * math.sin(t)),
            bounds=bounds,
            method="bounded",
            options={"xatol": 1e-12},
        ).x
        assert settled[row] == pytest.approx(well, abs=1e-7)  # Brent's minimum: good to √ε of the angle
        root = optimize.brentq(
            lambda t, bx=bx, by=by: KM * t + M * (bx * math.sin(t) - by * math.cos(t)), well - 1e-3, well + 1e-3
        )
        assert settled[row] == pytest.approx(root, abs=1e-11)  # the 24-node series: 1e-12 rad
        assert math.radians(15.0) < abs(well) < math.radians(35.0)
        assert potential.stiffness_nm_per_rad(settled)[row] > 0.0
    assert np.isnan(settled[3])


def test_spring_cancellation_drives_the_frequency_to_zero():
    b_cancel = P.cancellation_field_t
    freqs = [along(b_cancel * (1 - eps)).frequency_hz() for eps in (1e-2, 1e-4)]
    # f ≈ f00·√ε near cancellation (damping makes it vanish slightly earlier).
    assert freqs[0] == pytest.approx(P.f00_hz * 0.1, rel=0.01)
    assert freqs[1] < 0.02 * P.f00_hz
    assert np.isnan(along(1.01 * b_cancel).frequency_hz())


def test_hanging_magnet_is_a_pendulum_of_about_150_microtesla():
    # docs/physics.md §9.5: gravity along the probe axis adds a·g·l, like a field a·g·l/m.
    g = 9.80665
    potential = ArcPotential.from_local_field(P, np.zeros(3), gravity_m_per_s2=np.array([g, 0.0, 0.0]))
    assert potential.stiffness_nm_per_rad() == pytest.approx(KM + P.magnet_mass_kg * g * P.lever_m, rel=1e-12)
    assert P.magnet_mass_kg * g * P.lever_m / M == pytest.approx(150e-6, rel=0.05)


def test_axial_gradient_of_a_divergence_free_field_doubles_the_published_term():
    # Axisymmetric gradient about x': Gx'x' = G, Gy'y' = Gz'z' = −G/2 (∇·B = 0).
    # docs/physics.md §6.1: k = kM + m·l·(Gx'x' − 2Gy'y') = kM + 2·m·l·G to first order in l.
    g = 20e-3
    gradient = np.diag([g, -g / 2, -g / 2])
    potential = ArcPotential.from_local_field(P, np.zeros(3), gradient_t_per_m=gradient)
    published = M * P.lever_m * g
    assert (potential.stiffness_nm_per_rad() - KM) / published == pytest.approx(2.0, rel=1e-3)


def test_batches_equal_single_evaluations():
    fields = np.array([[1e-4, 0, 0], [0, 2e-4, 0], [-3e-3, 1e-4, 5e-5]])
    amplitudes = np.radians([0.0, 10.0, 24.0])
    batch = ArcPotential.from_local_field(P, fields).frequency_hz(amplitudes)
    single = [ArcPotential.from_local_field(P, f).frequency_hz(a) for f, a in zip(fields, amplitudes)]
    np.testing.assert_allclose(batch, single, rtol=1e-13)


def test_the_compiled_kernels_are_given_writable_arrays_whatever_the_caller_passes():
    """numba compiles a kernel again for a read-only argument (what np.broadcast_to gives), a
    second or more of CPU in every process the precompiled cache does not hold it for."""
    from numba import types

    from mows.physics import harmonic_balance, potential

    batch = ArcPotential.from_local_field(P, np.array([[1e-4, 0, 0], [0, 2e-4, 0], [-3e-3, 1e-4, 5e-5]]))
    batch.frequency_hz(np.radians([0.0, 10.0, 24.0]))  # an amplitude per row, as given
    batch.frequency_hz(np.radians(10.0))  # one for all rows, broadcast
    batch.first_harmonic_rad(np.broadcast_to(np.radians(16.0), batch.batch_shape))
    batch.torque_nm(np.broadcast_to(np.radians([1.0, 2.0]), (3, 2)))
    for kernel in (harmonic_balance.balance_rows, harmonic_balance.centre_rows, potential._clenshaw_rows):
        arrays = [arg for signature in kernel.signatures for arg in signature if isinstance(arg, types.Array)]
        assert arrays and all(arg.mutable for arg in arrays), kernel


def free_swing(potential, start_rad, periods=1.2):
    """The undamped swing released at rest from ``start_rad``, integrated by solve_ivp:
    (its frequency from two successive turning points, its first-harmonic amplitude)."""

    def motion(_, y):
        return [y[1], float(potential.torque_nm(np.array(y[0]))) / P.inertia_kgm2]

    def turning(_, y):
        return y[1]

    guess_s = 1.0 / float(potential.frequency_hz(0.0))
    solution = integrate.solve_ivp(
        motion, (0.0, periods * guess_s), [start_rad, 0.0], rtol=1e-12, atol=1e-15, dense_output=True, events=turning
    )
    period_s = solution.t_events[0][solution.t_events[0] > 0.1 * guess_s][1]
    t = np.linspace(0.0, period_s, 2001)[:-1]
    first_harmonic = 2.0 * np.mean(solution.sol(t)[0] * np.cos(2.0 * np.pi * t / period_s))
    return 1.0 / period_s, first_harmonic


@pytest.mark.parametrize("across_deg", [30.0, 90.0])
@pytest.mark.parametrize("turning_deg", [8.0, 16.0, -16.0])
def test_a_deflected_swing_has_the_frequency_and_first_harmonic_of_the_integrated_motion(across_deg, turning_deg):
    """3.4 mT at θ0 = 180° − across: the rest angle turns by 8°–12° and the potential is
    lopsided about it. A swing released at θs + turning: its first harmonic follows from the
    turning point within 0.01° (0.002° measured; the turning distance itself is 0.03°–0.16°
    off), and the balance with the second harmonic gives its frequency within 0.05 mHz of an
    independent integration (0.012 mHz measured), where first-harmonic balance alone (the cycle
    centre from the mean balance, then the cos φ part) is 1–9 mHz low, several times a fit's
    σ of 0.3–0.6 mHz."""
    undamped = P.replace(damping_per_s=0.0)
    across = math.radians(across_deg)
    field = 3.4e-3 * np.array([-math.cos(across), math.sin(across), 0.0])
    potential = ArcPotential.from_local_field(undamped, field)
    rest = float(potential.rest_angle_rad())
    assert abs(math.degrees(rest)) > 7.0
    turning = math.radians(turning_deg)
    exact_hz, signed_amplitude = free_swing(potential, rest + turning)
    amplitude = abs(signed_amplitude)
    assert math.degrees(abs(float(potential.first_harmonic_rad(turning)) - amplitude)) < 0.01
    assert math.degrees(abs(abs(turning) - amplitude)) > 0.02
    assert float(potential.frequency_hz(amplitude)) == pytest.approx(exact_hz, abs=5e-5)

    phi = 2.0 * np.pi * np.arange(64) / 64
    theta = float(potential.cycle_centre_rad(amplitude)) + amplitude * np.cos(phi)
    first_only_nm_per_rad = -2.0 * np.mean(potential.torque_nm(theta[None])[0] * np.cos(phi)) / amplitude
    first_only_hz = math.sqrt(first_only_nm_per_rad / P.inertia_kgm2) / (2.0 * math.pi)
    assert exact_hz - first_only_hz > 1e-3


def test_a_ring_down_released_at_the_nearer_stop_starts_with_its_first_harmonic():
    """The rest angle turns towards one stop (θs < 0 here); the swing released there (24° from
    θ0) is what a fit's θmax measures; a stop inside the deflection leaves no free swing."""
    undamped = P.replace(damping_per_s=0.0)
    across = math.radians(-30.0)
    potential = ArcPotential.from_local_field(undamped, 3.4e-3 * np.array([-math.cos(across), math.sin(across), 0.0]))
    rest = float(potential.rest_angle_rad())
    assert rest < 0.0
    stop = math.radians(24.0)
    _, amplitude = free_swing(potential, -stop)
    assert math.degrees(abs(float(potential.start_swing_rad(stop)) - abs(amplitude))) < 0.01
    assert math.isnan(float(potential.start_swing_rad(0.5 * abs(rest))))
