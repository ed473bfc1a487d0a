"""A recorded session for the viz tests: simulated cycles streamed as the driver records them
(tests/recorded_bags.py), each fitted as the estimator fits it (its RingdownFit in the bag, at
its window's device time), each cycle's excitation with its coil currents, and what the graph
concludes later: a sweep, the lab's model reports after three sweeps, the stage's joint state and
/diagnostics."""

import numpy as np

from mows.device.recording import bags
from mows.estimate.recorded_cycle import fit_cycle
from mows.sim.scenario import load_scenario
from recorded_bags import STORE, header, record_cycles, ringdown_message

DEGREES = (0.0, 60.0)
SWEEP = {  # in-plane B (T) and gradient (Gxx, Gxy, Gyy, T/m) with covariances
    "field_t": np.array([3.0e-5, -1.0e-5]),
    "field_covariance_t2": np.diag([4e-14, 1e-14]).ravel(),
    "gradient_t_per_m": np.array([2.0e-4, 5.0e-5, -2.0e-4]),
    "gradient_covariance": np.diag([1e-12, 4e-12, 9e-12]).ravel(),
}
LAB_ERRORS_HZ = ((1, 0.05), (2, 0.03), (3, 0.02))  # the model reports' sweeps and cv_rms_hz


def fit_message(fit, start_ns: int, cycle: int):
    """The estimator's RingdownFit of ``fit`` (mows_estimator.messages.fit_to_msg's fields)."""
    numbers = {
        name: float(getattr(fit, name))
        for name in (
            "theta0_rad", "frequency_hz", "frequency_std_hz", "frequency_crb_hz", "damping_per_s", "amplitude_rad",
            "rest_offset_rad", "phase_rad", "kappa_t", "offset_t", "chi2_dof", "r_squared", "snr_db", "duration_s",
            "start_offset_s",
        )
    }  # fmt: skip
    pickup = np.asarray(fit.pickup, complex)
    msg = STORE.types["mows_msgs/msg/RingdownFit"](
        header=header(start_ns / 1e9, "mows_probe"),
        cycle_id=cycle,
        repeat_index=0,
        tuning=False,
        status=int(fit.status),
        status_name=fit.status.name,
        message=fit.message,
        probe_id=0,
        theta0_free=False,
        frequency_shift_hz=0.0,
        frequency_shift_std_hz=0.0,
        n_samples=int(fit.n_samples),
        parameter_names=list(fit.parameter_names),
        covariance=np.asarray(fit.covariance, float).ravel(),
        pickup_real=pickup.real.copy(),
        pickup_imag=pickup.imag.copy(),
        **numbers,
    )
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(start_ns, 1_000_000_000)
    return msg


def sweep_message(seconds: float):
    theta = np.radians([0.0, 60.0, 120.0, 180.0, 240.0, 300.0])
    amplitude, phase = np.array([0.5, 1.2, 0.3]), np.array([0.0, 0.4, -0.2])
    shift = np.cos(np.multiply.outer(theta, np.arange(3)) + phase) @ amplitude
    return STORE.types["mows_msgs/msg/SweepDecomposition"](
        header=header(seconds, "mows_rotation_plane"),
        sweep_id=1,
        status=0,
        message="",
        model="first_principles",
        probe_id=0,
        f00_hz=112.5,
        f00_free=False,
        harmonic_amplitude_hz=amplitude,
        harmonic_phase_rad=phase,
        theta0_rad=theta,
        cycle_ids=np.arange(1, theta.size + 1, dtype=np.uint64),
        frequency_shift_hz=shift,
        frequency_shift_std_hz=np.full(theta.size, 0.01),
        chi2_dof=1.1,
        rms_residual_hz=0.004,
        n_points=theta.size,
        **SWEEP,
    )


def model_report_message(seconds: float, sweep_id: int, cv_rms_hz: float):
    return STORE.types["mows_msgs/msg/ModelReport"](
        header=header(seconds),
        sweep_id=sweep_id,
        model="first_principles",
        effects=["gravity"],
        n=12,
        chi2_dof=1.3,
        bic=-40.0,
        cv_rms_hz=cv_rms_hz,
        verdict="adequate",
        structure="none",
        candidates=[],
    )


def exciting_message(record, cycle: int):
    """The driver's ExcitationState as ``record``'s coils start: phase EXCITING, its currents."""
    fs = record.sample_rate_hz
    msg = ringdown_message(record.block.samples.first_sample_index, fs, cycle, record.theta0_rad, record.frequency_hz)
    msg.phase, msg.phase_name, msg.coils_on = 2, "EXCITING", True
    msg.coil_current_amplitude_a = np.asarray(record.currents_a, float)
    return msg


def joint_state_message(seconds: float, theta0_rad: float):
    return STORE.types["sensor_msgs/msg/JointState"](
        header=header(seconds), name=["mows_stage"], position=np.array([theta0_rad]), velocity=np.zeros(0),
        effort=np.zeros(0),
    )  # fmt: skip


def diagnostics_message(seconds: float):
    status = STORE.types["diagnostic_msgs/msg/DiagnosticStatus"](
        level=0, name="/driver", message="up", hardware_id="",
        values=[STORE.types["diagnostic_msgs/msg/KeyValue"](key="lifecycle_state", value="active")],
    )  # fmt: skip
    return STORE.types["diagnostic_msgs/msg/DiagnosticArray"](header=header(seconds), status=[status])


def recorded_session(directory):
    """(the bag's path, the fits in cycle order) of module docstring's session."""
    scenario = load_scenario()
    raw_bag, records = record_cycles(directory / "raw", scenario, DEGREES, 5)
    messages = list(bags.read_bag(raw_bag))
    fits = []
    for cycle, record in enumerate(records, start=1):
        fit = fit_cycle(record, scenario)
        first = record.block.samples.first_sample_index + record.coil_off_index
        start_ns = round(first / record.sample_rate_hz * 1e9) + round(fit.start_offset_s * 1e9)
        end_ns = start_ns + round(fit.duration_s * 1e9)
        messages.append(
            bags.BagMessage("/mows/ringdown", "mows_msgs/msg/RingdownFit", end_ns, fit_message(fit, start_ns, cycle))
        )
        messages.append(
            bags.BagMessage(
                "/mows/joint_states",
                "sensor_msgs/msg/JointState",
                start_ns,
                joint_state_message(start_ns / 1e9, record.theta0_rad),
            )
        )
        messages.append(
            bags.BagMessage(
                "/mows/excitation",
                "mows_msgs/msg/ExcitationState",
                round(record.block.samples.first_sample_index / record.sample_rate_hz * 1e9),
                exciting_message(record, cycle),
            )
        )
        fits.append(fit)
    last = max(m.timestamp_ns for m in messages)
    conclusions = [
        ("/mows/sweep", "mows_msgs/msg/SweepDecomposition", sweep_message(last / 1e9)),
        *(
            ("/mows/model_report", "mows_msgs/msg/ModelReport", model_report_message(last / 1e9, sweep, cv_rms_hz))
            for sweep, cv_rms_hz in LAB_ERRORS_HZ
        ),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", diagnostics_message(last / 1e9)),
    ]
    for offset, (topic, msgtype, msg) in enumerate(conclusions, start=1):
        messages.append(bags.BagMessage(topic, msgtype, last + offset * 1000, msg))
    messages.sort(key=lambda m: m.timestamp_ns)
    return bags.write_bag(directory / "session", messages), fits


# The session of docs/visualisation.md's pictures: PYTHONPATH=src:tests python -m viz.session DIR
if __name__ == "__main__":
    import sys
    from pathlib import Path

    print(recorded_session(Path(sys.argv[1]))[0])
