"""The multi-tone coil drive, its cap and its grouping, against independent physics.

Requirements: one tone is today's single-probe drive (to 1e-12 A); the summed waveform's
spectrum holds each tone at its scheme amplitude; the summed current of a planned group never
exceeds the cap over randomized probes (checked on a grid of its own, finer than the drive's);
overlapping tones are refused and a sum above the cap is split into groups, each with its
reason; the cross-talk rule bounds the exact driven-oscillator response; and two coupled
probes driven by the multi-tone drive ring up as the linear driven-oscillator solution says:
each to its own tone's amplitude, the other tone adding no more than its cross-talk.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate

from mows.physics.coils import helmholtz, largest_spacing
from mows.physics.coupling import PlacedProbe, coupled_frequencies_hz, coupled_rest
from mows.physics.multitone import (
    Tone,
    coil_amplitudes_a,
    crosstalk,
    drive_currents_a,
    peak_current_a,
    plan_excitation,
    required_separation_hz,
)
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE as P
from mows.physics.sources import UniformField
from scenes import scene_device

SETUP = largest_spacing()
DELTA = P.damping_per_s


def tone(probe_id, frequency_hz, theta0_rad=0.3, amplitude_a=2.0):
    return Tone(probe_id, frequency_hz, theta0_rad, amplitude_a, DELTA)


@pytest.mark.parametrize("setup", [largest_spacing(), helmholtz()], ids=["largest_spacing", "helmholtz"])
def test_one_tone_is_the_single_probe_drive(setup):
    rng = np.random.default_rng(1)
    times = np.arange(5000) / 10_000.0
    for _ in range(20):
        theta0, amplitude, frequency = rng.uniform(-np.pi, np.pi), rng.uniform(0, 10), rng.uniform(80, 160)
        today = setup.currents_a(theta0, amplitude)[None, :] * np.sin(2 * np.pi * frequency * times)[:, None]
        summed = drive_currents_a(setup, [Tone(0, frequency, theta0, amplitude, DELTA)], times)
        assert np.abs(summed - today).max() <= 1e-12
        # A sine's peak over more than a quarter period is its amplitude A·|sin(θ0 + φ_c)|.
        expected = amplitude * np.abs(np.sin(theta0 + np.array(setup.phases_rad)))
        peak = peak_current_a(setup, [Tone(0, frequency, theta0, amplitude, DELTA)], 0.5)
        assert peak == pytest.approx(expected, rel=0, abs=1e-12 + 1e-4 * amplitude)
        assert np.all(peak >= expected - 1e-12)


def test_the_spectrum_holds_each_tone_at_its_amplitude():
    # Whole periods of every tone in 1 s: each tone falls on one FFT bin, no leakage.
    rate_hz, tones = 10_000.0, [tone(0, 100.0, 0.2, 3.0), tone(1, 112.0, 1.4, 2.0), tone(2, 125.0, -2.1, 1.5)]
    times = np.arange(int(rate_hz)) / rate_hz
    spectrum = np.fft.rfft(drive_currents_a(SETUP, tones, times), axis=0) * 2.0 / times.size
    bins = [100, 112, 125]
    for k, t in enumerate(tones):
        # sin(θ0 + φ_c) by hand, the paper's scheme for the largest spacing: φ = (135°, 45°).
        expected = t.amplitude_a * np.sin(t.theta0_rad + np.radians([135.0, 45.0]))
        # A·sin(ωt) has the Fourier coefficient −i·A.
        assert spectrum[bins[k]] == pytest.approx(-1j * expected, abs=1e-9)
    others = np.delete(np.abs(spectrum), bins, axis=0)
    assert others.max() < 1e-9


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(80.0, 160.0),
            st.floats(-math.pi, math.pi),
            st.floats(0.0, 10.0),
        ),
        min_size=1,
        max_size=4,
    ),
    st.floats(0.05, 1.0),
)
def test_a_planned_group_never_exceeds_the_cap(draws, duration_s):
    tones = [Tone(k, f, theta0, a, DELTA) for k, (f, theta0, a) in enumerate(draws)]
    plan = plan_excitation(SETUP, tones, duration_s)
    assert sorted([i for g in plan.groups for i in g] + [i for i, _ in plan.refused]) == list(range(len(tones)))
    assert len(plan.reasons) == len(plan.groups) and all(reason for _, reason in plan.refused)
    # An independent grid: 400 points per period of the fastest tone, offset from the planner's.
    fastest_hz = max(f for f, _, _ in draws)
    times = np.arange(0.3 / (400 * fastest_hz), duration_s, 1.0 / (400 * fastest_hz))
    for index in range(len(plan.groups)):
        group = plan.group_tones(index)
        currents = np.abs(drive_currents_a(SETUP, group, times)).max(axis=0)
        assert np.all(currents <= SETUP.cap.limit_a)
        assert np.all(currents <= peak_current_a(SETUP, group, duration_s) + 1e-12)  # an upper bound


def test_the_cap_holds_the_true_peak_not_each_tone_nor_the_sum_of_amplitudes():
    # Each 5 A tone alone passes the single-probe check, but the three summed exceed the cap.
    strong = [tone(k, f, 0.3, 5.0) for k, f in enumerate((100.0, 112.0, 125.0))]
    assert all(np.abs(SETUP.currents_a(t.theta0_rad, t.amplitude_a)).max() <= 10.0 for t in strong)
    times = np.arange(0.0, 0.5, 1e-5)
    assert np.abs(drive_currents_a(SETUP, strong, times)).max() > SETUP.cap.limit_a
    # Tones on a 12.5 Hz comb repeat every 80 ms, so their phases never line up: 4 A at these
    # orientations sum to 11.5 A of amplitude on coil 2, yet the current never passes 8.6 A.
    comb = [tone(0, 100.0, 0.3, 4.0), tone(1, 112.5, 0.8, 4.0), tone(2, 125.0, -2.4, 4.0)]
    assert np.abs(coil_amplitudes_a(SETUP, comb)).sum(axis=0).max() > 11.5
    assert np.abs(drive_currents_a(SETUP, comb, np.arange(0.0, 0.08, 1e-6))).max() < 8.6
    assert plan_excitation(SETUP, comb, 0.5).groups == ((0, 1, 2),)


def test_overlapping_tones_are_refused_and_a_sum_above_the_cap_is_split():
    # 4 Hz apart in a 0.5 s excitation: less than the 6.8 Hz the paper's probe needs for ρ ≤ 0.1.
    assert required_separation_hz(DELTA, 0.5, 0.1) == pytest.approx(6.784, abs=1e-3)
    plan = plan_excitation(SETUP, [tone(0, 112.0), tone(1, 116.0)], 0.5)
    assert plan.groups == ((0,),)
    assert plan.refused[0][0] == 1 and "4 Hz from probe 0" in plan.refused[0][1]
    # Three tones of 5 A at θ0 = 0.3 rad: 4.42 A each on coil 2, two fit in the 10 A cap, three not.
    strong = [tone(k, f, 0.3, 5.0) for k, f in enumerate((100.0, 112.0, 125.0))]
    plan = plan_excitation(SETUP, strong, 0.5)
    assert not plan.refused
    assert len(plan.groups) == 2 and "cap" in plan.reasons[1]
    for index in range(2):
        assert peak_current_a(SETUP, plan.group_tones(index), 0.5).max() <= SETUP.cap.limit_a
    # A tone alone above the cap is refused, never clipped.
    plan = plan_excitation(SETUP, [tone(0, 112.0, amplitude_a=12.0)], 0.5)
    assert plan.groups == () and "cap" in plan.refused[0][1]


def test_bad_input_is_refused_with_the_value():
    with pytest.raises(ValueError, match="frequency_hz = -1"):
        tone(0, -1.0)
    with pytest.raises(ValueError, match="duration_s = 0"):
        plan_excitation(SETUP, [tone(0, 112.0)], 0.0)
    with pytest.raises(ValueError, match="distinct"):
        plan_excitation(SETUP, [tone(0, 112.0), tone(0, 125.0)], 0.5)
    tilted = PlacedProbe(P, Pose(plane_e1=(1.0, 0.0, 0.0), plane_e2=(0.0, 0.0, 1.0)))
    with pytest.raises(ValueError, match="x–y plane"):
        Tone.of(0, tilted, 112.0, 2.0)


def forced_state(force, omega_drive, omega0, delta, t):
    """(x, x') of x'' + 2δx' + ω0²x = F·sin(ωt) from rest, the exact solution written out."""
    response = force / (omega0**2 - omega_drive**2 + 2j * delta * omega_drive)
    x_p = lambda s: (response * np.exp(1j * omega_drive * s)).imag  # noqa: E731
    v_p = lambda s: (1j * omega_drive * response * np.exp(1j * omega_drive * s)).imag  # noqa: E731
    omega_d = math.sqrt(omega0**2 - delta**2)
    c1 = -x_p(0.0)
    c2 = (-v_p(0.0) + delta * c1) / omega_d
    decay, c, s = math.exp(-delta * t), math.cos(omega_d * t), math.sin(omega_d * t)
    x = x_p(t) + decay * (c1 * c + c2 * s)
    v = v_p(t) + decay * ((-delta * c1 + omega_d * c2) * c + (-delta * c2 - omega_d * c1) * s)
    return np.array([x, v])


def ringdown_amplitude(state, omega0, delta):
    """The free swing amplitude that follows a state (x, x') once the drive is off."""
    x, v = state
    return math.hypot(x, (v + delta * x) / math.sqrt(omega0**2 - delta**2))


@pytest.mark.parametrize("duration_s", [0.1, 0.5, 2.0])
def test_the_crosstalk_bound_holds_for_the_exact_driven_oscillator(duration_s):
    omega0 = 2 * math.pi * 112.48

    def ratio(detuning_hz, t):
        """Ring-down swing after a drive of t detuned by ``detuning_hz``, per swing on resonance."""
        on = ringdown_amplitude(forced_state(1.0, omega0, omega0, DELTA, t), omega0, DELTA)
        off = forced_state(1.0, omega0 + 2 * math.pi * detuning_hz, omega0, DELTA, t)
        return ringdown_amplitude(off, omega0, DELTA) / on

    for detuning_hz in (2.0, 5.0, 6.8, 10.0, 20.0):
        # The rotating-wave terms it neglects are of relative size Δω/ω0 (≤ 0.18 here).
        slack = 1.0 + 2.0 * detuning_hz / 112.48
        for t in np.linspace(0.5, 1.0, 21) * duration_s:
            assert ratio(detuning_hz, t) <= crosstalk(detuning_hz, DELTA, t) * slack
        # Cut half a beat after a whole number of beats, the drive and the ring are in
        # antiphase: the bound is reached there.
        half_beat_s = (max(round(detuning_hz * duration_s - 0.5), 0) + 0.5) / detuning_hz
        assert ratio(detuning_hz, half_beat_s) >= crosstalk(detuning_hz, DELTA, half_beat_s) / slack


NO_FIELD = UniformField([0.0, 0.0, 0.0])
STIFFER = P.replace(spring_nm_per_rad=P.spring_nm_per_rad * 1.24)  # f00 ≈ 125 Hz


def test_two_coupled_probes_ring_up_to_their_own_tones():
    # The paper's probe at the coils' centre and a 125 Hz probe 4 cm from it, turned differently.
    placed = [
        PlacedProbe(P, Pose(theta0_rad=0.4)),
        PlacedProbe(STIFFER, Pose(magnet_position_m=(0.0, 0.04, 0.0), theta0_rad=1.3)),
    ]
    probes = scene_device(placed)
    frequencies = coupled_frequencies_hz(placed, NO_FIELD)
    rest = coupled_rest(placed, NO_FIELD).rest_angle_rad
    tones = [Tone.of(k, p, f, 0.05) for k, (p, f) in enumerate(zip(placed, frequencies))]
    duration_s = 0.5
    amplitudes = coil_amplitudes_a(SETUP, tones)  # (tone, coil)
    magnets = np.array([p.pose.magnet_position_at(r, p.probe.lever_m) for p, r in zip(placed, rest)])
    per_ampere = SETUP.coil_field_per_ampere_t(magnets)  # (probe, coil, 3)

    def turning(i, theta):
        x_axis, y_axis, _ = placed[i].pose.axes()
        return -math.sin(theta) * x_axis + math.cos(theta) * y_axis

    omegas = 2 * math.pi * frequencies
    inertia = np.array([p.probe.inertia_kgm2 for p in placed])

    def run(active):
        base = probes.equation_of_motion()
        # The drive of the tones ``active``: Σ_k A_kc·sin(ω_k·t), what drive_currents_a sums.
        scheme = amplitudes[active]

        def rhs(t, y):
            currents = np.sin(omegas[active] * t) @ scheme
            torque = [p.probe.moment_am2 * turning(i, y[i]) @ (currents @ per_ampere[i]) for i, p in enumerate(placed)]
            out = base(t, y)
            out[2:] += np.array(torque) / inertia
            return out

        # At rtol 1e-7 the end state is that of rtol 1e-10 to 1e-6 of the swing: far inside 1 %.
        y = integrate.solve_ivp(rhs, (0, duration_s), np.r_[rest, 0, 0], method="DOP853", rtol=1e-7, atol=1e-10).y
        return [(y[i, -1] - rest[i], y[2 + i, -1]) for i in range(2)]

    def predicted(i, k):
        """Probe i's state at the end from tone k alone: the linear driven oscillator."""
        torque = placed[i].probe.moment_am2 * turning(i, rest[i]) @ (amplitudes[k] @ per_ampere[i])
        force = torque / placed[i].probe.inertia_kgm2
        omega0 = 2 * math.pi * frequencies[i]
        return forced_state(force, 2 * math.pi * frequencies[k], omega0, placed[i].probe.damping_per_s, duration_s)

    both, alone = run([0, 1]), [run([0]), run([1])]
    for i in range(2):
        omega0, delta = 2 * math.pi * frequencies[i], placed[i].probe.damping_per_s
        intended = ringdown_amplitude(predicted(i, i), omega0, delta)
        assert 0.005 < intended < 0.05  # rad: a swing in the linear range
        other = 1 - i
        # The other tone alone: the linear response at the separation, which the ρ rule bounds.
        cross = ringdown_amplitude(alone[other][i], omega0, delta)
        assert cross == pytest.approx(ringdown_amplitude(predicted(i, other), omega0, delta), rel=0.05)
        own_torque = abs(turning(i, rest[i]) @ (amplitudes[i] @ per_ampere[i]))
        cross_torque = abs(turning(i, rest[i]) @ (amplitudes[other] @ per_ampere[i]))
        detuning_hz = frequencies[other] - frequencies[i]
        assert cross / intended <= 1.1 * crosstalk(detuning_hz, delta, duration_s) * cross_torque / own_torque
        # Both tones: the intended swing, within what the other tone adds.
        measured = ringdown_amplitude(both[i], omega0, delta)
        assert measured == pytest.approx(intended, rel=0.01 + cross / intended)
        assert ringdown_amplitude(alone[i][i], omega0, delta) == pytest.approx(intended, rel=0.01)
