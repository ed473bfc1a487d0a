"""Driver-like rosbag2 bags of simulated cycles, for the tests that read recorded raw samples
(``mows fit BAG``, ``mows lab ringdown BAG``): each cycle's samples streamed as MagnetometerBlock
messages and its ring-down announced by an ExcitationState at the coil-off sample."""

import math

import numpy as np

from mows.device.recording import bags
from mows.device.stream.simulated_cycle import simulate_cycle
from mows.sim.simulator import SimulatedDevice

STORE = bags.typestore()
RAW, EXCITATION = "mows_msgs/msg/MagnetometerBlock", "mows_msgs/msg/ExcitationState"
BLOCK = 500


def stamp(seconds):
    Time = STORE.types["builtin_interfaces/msg/Time"]
    whole = math.floor(seconds)
    return Time(sec=int(whole), nanosec=int(round((seconds - whole) * 1e9)))


def header(seconds, frame="mows"):
    return STORE.types["std_msgs/msg/Header"](stamp=stamp(seconds), frame_id=frame)


def block_message(first, fs, samples, saturated):
    Channel = STORE.types["mows_msgs/msg/MagnetometerChannel"]
    channels = [
        Channel(
            frame_id=f"fluxgate_{i}",
            field_t=np.ascontiguousarray(samples[:, i]),
            saturated=np.ascontiguousarray(saturated[:, i]),
        )
        for i in range(2)
    ]
    return STORE.types[RAW](
        header=header(first / fs),
        sequence=first // BLOCK,
        device_epoch=0,
        first_sample_index=first,
        sample_rate_hz=fs,
        range_t=1e-5,
        resolution_t=1e-10,
        channels=channels,
    )


def ringdown_message(index, fs, cycle, theta0, frequency):
    return STORE.types[EXCITATION](
        header=header(index / fs),
        phase=3,
        phase_name="RINGDOWN",
        cycle_id=cycle,
        device_epoch=0,
        repeat_index=0,
        repeats=1,
        tuning=False,
        coils_on=False,
        coil_current_amplitude_a=np.zeros(2),
        frequency_hz=frequency,
        theta0_rad=theta0,
        planned_duration_s=0.5,
        setup="largest_spacing",
        probe_ids=np.zeros(0, np.uint8),  # one probe: no multi-tone list
        probe_frequency_hz=np.zeros(0),
        probe_theta0_rad=np.zeros(0),
    )


def ringdown_fit_message(seconds, theta0_rad, frequency_hz, status=0, probe_id=0, amplitude_rad=0.4, determined=()):
    """An estimator's RingdownFit stamped at ``seconds`` (cycle id the whole seconds): σ 1 mHz,
    δ 1.8 s⁻¹ over 0.5 s; ``determined`` names the fitted parameters given σ 0.01 rad in its
    covariance; every other number 0."""
    values = {
        name: 0.0
        for name, (kind, detail) in STORE.fielddefs["mows_msgs/msg/RingdownFit"][1]
        if kind.name == "BASE" and detail[0] == "float64"
    }
    values.update(
        theta0_rad=theta0_rad,
        frequency_hz=frequency_hz,
        frequency_std_hz=1e-3,
        amplitude_rad=amplitude_rad,
        damping_per_s=1.8,
        duration_s=0.5,
    )
    return STORE.types["mows_msgs/msg/RingdownFit"](
        header=header(seconds),
        cycle_id=int(seconds),
        repeat_index=0,
        tuning=False,
        status=status,
        status_name="",
        message="",
        probe_id=probe_id,
        theta0_free=False,
        n_samples=10000,
        parameter_names=list(determined),
        covariance=1e-4 * np.eye(len(determined)).ravel(),
        pickup_real=np.zeros(0),
        pickup_imag=np.zeros(0),
        **values,
    )


def record_cycles(path, scenario, degrees, seed):
    """Write a bag at ``path`` of one simulated cycle at each orientation in ``degrees`` (cycle ids
    from 1); return (the bag's path, the cycles' :class:`mows.device.stream.simulated_cycle.CycleRecord`)."""
    device = SimulatedDevice(scenario, np.random.default_rng(seed))
    messages, records = [], []
    for cycle, deg in enumerate(degrees, start=1):
        record = simulate_cycle(device, math.radians(deg), scenario.excitation.amplitude_a)
        fs = record.sample_rate_hz
        first = record.block.samples.first_sample_index
        off = first + record.coil_off_index
        messages.append(
            bags.BagMessage(
                "/mows/excitation",
                EXCITATION,
                int(off / fs * 1e9),
                ringdown_message(off, fs, cycle, record.theta0_rad, record.frequency_hz),
            )
        )
        for start in range(0, len(record.samples_t), BLOCK):
            index = first + start
            messages.append(
                bags.BagMessage(
                    "/mows/raw",
                    RAW,
                    int(index / fs * 1e9),
                    block_message(
                        index, fs, record.samples_t[start : start + BLOCK], record.saturated[start : start + BLOCK]
                    ),
                )
            )
        records.append(record)
    messages.sort(key=lambda m: m.timestamp_ns)
    return bags.write_bag(path, messages), records


def excitation_message(event):
    """The driver's ExcitationState of a session's PhaseEvent (with the probes it lists)."""
    return STORE.types[EXCITATION](
        header=header(event.stamp_ns / 1e9),
        phase=int(event.phase),
        phase_name=event.phase.name,
        cycle_id=event.cycle_id,
        device_epoch=0,
        repeat_index=event.repeat_index,
        repeats=event.repeats,
        tuning=event.tuning,
        coils_on=event.coils_on,
        coil_current_amplitude_a=np.zeros(2),
        frequency_hz=event.frequency_hz,
        theta0_rad=event.theta0_rad,
        planned_duration_s=event.planned_duration_s,
        setup=event.setup,
        probe_ids=np.array(event.probe_ids, np.uint8),
        probe_frequency_hz=np.array(event.probe_frequency_hz, float),
        probe_theta0_rad=np.array(event.probe_theta0_rad, float),
    )


def record_session(path, scenario, stage_rad, settings, seed, max_steps=100_000):
    """Write a bag at ``path`` of one driver cycle at stage angle ``stage_rad`` on the simulated
    device of ``scenario`` (all its probes rung by one multi-tone excitation per repeat of
    ``settings``): its excitation states and raw blocks as the driver records them. Returns (the
    bag's path, each probe's frequency at zero swing in the cycle's field and its neighbours'
    (:meth:`SimulatedDevice.expected_frequencies_hz`))."""
    from mows.device.backends.sim_backend import SimBackend
    from mows.device.cycle.phases import CycleRequest
    from mows.device.stream.session import DeviceSession, SessionConfig
    from mows.estimate.ringdown import fit_tuning
    from mows.physics.coils import CurrentCap

    cap = CurrentCap(10.0)
    device = SimulatedDevice(scenario, np.random.default_rng(seed))
    backend = SimBackend(device, cap, paced=False, chunk_s=0.1)
    config = SessionConfig(0.025, settings, scenario.setup, cap, scenario.probe.f00_hz, fit_tuning)
    session = DeviceSession(backend, config, armed=True)
    events, blocks, done = list(session.step(0.0).events), [], []
    session.start_cycle(CycleRequest(stage_rad), done.append)
    for _ in range(max_steps):
        if done:
            break
        output = session.step(0.0)
        events += output.events
        blocks += output.blocks
    assert done and done[0].success, done
    messages = [bags.BagMessage("/mows/excitation", EXCITATION, e.stamp_ns, excitation_message(e)) for e in events]
    for b in blocks:
        message = block_message(b.first_sample_index, b.sample_rate_hz, b.samples_t, b.saturated)
        message.header = header(b.stamp_ns / 1e9)
        messages.append(bags.BagMessage("/mows/raw", RAW, b.stamp_ns, message))
    messages.sort(key=lambda m: m.timestamp_ns)
    return bags.write_bag(path, messages), device.expected_frequencies_hz()
