"""The simulated device with a scene of several probes, against an independent integration.

Requirement: the device's compiled RK4 of all probes together, under the multi-tone coil drive
and each other's fields, follows the equation of motion written directly from the fields
(torque = ∂m/∂θ·B + m·G·∂r/∂θ of the scene, the coils at their summed currents and every
neighbour's dipole at its current deflection, by the sources' own field and gradient) integrated
by scipy's DOP853; its fluxgates read the sum of every magnet's dipole field.
"""

import numpy as np
import pytest
from scipy import integrate

from mows.physics.fluxgate import NoiseModel
from mows.physics.multitone import Tone, coil_amplitudes_a, drive_currents_a
from mows.physics.sources import PointDipole
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

QUIET = load_scenario("three_probes").replace(noise=NoiseModel())


def direct_rhs(device, tones, t_on_s):
    """θ'' from the fields themselves, for the probes at the device's present orientations."""
    placed, setup, scene = device.placed, device.setup, device.static_source
    springs, count = device.truth.spring_nm_per_rad, len(placed)

    def rhs(t, y):
        theta, omega = y[:count], y[count:]
        moments = [p.probe.moment_am2 * p.pose.moment_direction_at(a) for p, a in zip(placed, theta)]
        positions = [p.pose.magnet_position_at(a, p.probe.lever_m) for p, a in zip(placed, theta)]
        currents = drive_currents_a(setup, tones, [t - t_on_s])[0] if tones else np.zeros(len(setup.coils))
        acceleration = np.empty(count)
        for i, p in enumerate(placed):
            x_axis, y_axis, _ = p.pose.axes()
            turning = -np.sin(theta[i]) * x_axis + np.cos(theta[i]) * y_axis
            sources = [scene, *(coil.scaled(c) for coil, c in zip(setup.coils, currents))]
            sources += [PointDipole(moments[j], positions[j]) for j in range(count) if j != i]
            field = sum(s.field_t(positions[i]) for s in sources)
            gradient = sum(s.gradient_t_per_m(positions[i]) for s in sources)
            magnetic = p.probe.moment_am2 * turning @ field + moments[i] @ gradient @ (p.probe.lever_m * turning)
            gravity = p.probe.magnet_mass_kg * p.probe.lever_m * turning @ np.asarray(p.pose.gravity_m_per_s2)
            spring = springs[i] * theta[i]
            acceleration[i] = (magnetic + gravity - spring) / p.probe.inertia_kgm2 - 2 * p.probe.damping_per_s * omega[
                i
            ]
        return np.concatenate([omega, acceleration])

    return rhs


@pytest.mark.slow  # DOP853 on loop fields: 30–45 s on a loaded machine
def test_the_driven_probes_follow_the_equation_of_motion_written_from_the_fields():
    device = SimulatedDevice(QUIET)
    device.set_orientations(device.theta0_rad + 0.3)
    frequencies = device.expected_frequencies_hz()
    tones = [Tone.of(k, p, f, 0.2) for k, (p, f) in enumerate(zip(device.placed, frequencies))]
    start = np.r_[device.truth.theta_rad, device.truth.theta_dot_rad_per_s]
    fs, driven, free = device.sample_rate_hz, 160, 80
    device.drive(coil_amplitudes_a(device.setup, tones), [t.frequency_hz for t in tones], driven)
    theta = device.read(driven + free).theta_rad
    times = np.arange(driven + free) / fs
    options = dict(method="DOP853", rtol=1e-10, atol=1e-12)
    on = integrate.solve_ivp(direct_rhs(device, tones, 0.0), (0, times[driven]), start, dense_output=True, **options)
    off = integrate.solve_ivp(
        direct_rhs(device, [], 0.0), (times[driven], times[-1]), on.y[:, -1], t_eval=times[driven:], **options
    )
    assert on.success and off.success
    reference = np.concatenate([on.sol(times[:driven])[:3].T, off.y[:3].T])
    swing = np.abs(theta - theta[0]).max(axis=0)
    assert np.all(swing > 0.005)  # every probe is rung up by its own tone
    assert np.abs(theta - reference).max() < 1e-7 * swing.max()  # 6e-9 measured


def test_the_fluxgates_read_every_magnet():
    device = SimulatedDevice(QUIET)
    device.set_orientations(device.theta0_rad + 0.5)
    block = device.read(10)
    pair, scene = QUIET.sensors.pair, device.static_source
    nulled = pair.with_offsets_nulled(scene.field_t(pair.positions_m))
    field = nulled.component_t(scene.field_t(pair.positions_m))
    for k, p in enumerate(device.placed):
        angle = block.theta_rad[:, k]
        moment = p.probe.moment_am2 * p.pose.moment_direction_at(angle)
        field = field + nulled.pickup_t(p.pose.magnet_position_at(angle, p.probe.lever_m), moment)
    one_probe = nulled.pickup_t(
        device.placed[2].pose.magnet_position_at(block.theta_rad[:, 2], device.placed[2].probe.lever_m),
        device.placed[2].probe.moment_am2 * device.placed[2].pose.moment_direction_at(block.theta_rad[:, 2]),
    )
    assert np.abs(one_probe).min() > 100 * pair.sensors[0].resolution_t  # the farthest probe is seen
    assert np.array_equal(block.samples.samples_t, nulled.digitise(field)[0])
