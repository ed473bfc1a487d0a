"""A rotation sweep and a probe calibration on the paper's bench backends (the NI card through
the ``nidaqmx`` Task API on the simulated bench, the NGM202 through PyVISA on pyvisa-sim), run
by the core's state machines as the mapper and the calibrator run them.

Requirement (the bench's Done-when): the sweep on the DAQmx and SCPI backends decomposes within
2σ of the true field and gradient, as the same sweep on the simulator backend does; a calibration
on each backend combination recovers the probe's constants. The scene: the calibration probe in
the Helmholtz setup with the Pasco pair anti-parallel on the supply at 0.5 A (Gxx ≈ +9.8 mT/m,
the Earth's field); six orientations, two ring-downs each.
"""

import dataclasses
import math

import numpy as np
import pytest

from device.bench_runs import BenchRig
from mows.device.daq import load_daq_device
from mows.device.daqmx_backend import open_daqmx
from mows.device.phases import CycleSettings
from mows.device.scpi import SIMULATED_RESOURCE, SIMULATED_SUPPLY_FILE, load_supply_file, open_scpi_supply
from mows.device.session import DeviceSession, SessionConfig
from mows.device.sim_backend import SimBackend
from mows.device.simulated_daqmx import SimulatedBench
from mows.estimate.calibration.constants import KnownConstants
from mows.estimate.calibration.fit import calibrate_probe
from mows.estimate.ringdown import fit_ringdown
from mows.lab import reference_at
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice
from mows.sweep.calibration.schedule import CalibrationPlan, scenario_wirings

SETTINGS = CycleSettings(excite_s=0.5, ringdown_s=0.5, gap_s=0.2, repeats=2, tuning_steps=1, turn_settle_s=0.5)
ANGLES_RAD = tuple(np.radians(np.arange(0.0, 360.0, 60.0)))
SUPPLY_A = 0.5
CAP = CurrentCap(10.0)


def sim_rig(scenario):
    backend = SimBackend(SimulatedDevice(scenario), CAP, paced=False, supply_cap_a=2.0, supply_slew_a_per_s=2.0)
    return BenchRig(session(backend, scenario), scenario), backend.device.device


def daqmx_rig(scenario):
    supply = open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(), f"{SIMULATED_SUPPLY_FILE}@sim")
    properties = supply.resource.visalib.devices[SIMULATED_RESOURCE]._properties
    bench = SimulatedBench(
        SimulatedDevice(scenario),
        supply_current_a=lambda: properties["current"].get_value() * properties["output"].get_value(),
    )
    # The rig decomposes between reads (the driver's stream never waits for the mapper): no watchdog.
    device = dataclasses.replace(load_daq_device(), watchdog_s=3600.0)
    backend = open_daqmx(device, CAP, supply, daqmx=bench.module())
    return BenchRig(session(backend, scenario), scenario, bench.turn_probe, manual=True), bench.device


def session(backend, scenario):
    config = SessionConfig(0.025, SETTINGS, scenario.setup, CAP, scenario.probe.f00_hz, fit_ringdown)
    return DeviceSession(backend, config, armed=True)


def pulls(decomposition, device):
    field, gradient = reference_at(device.static_source, device.scenario.pose.magnet_position_m)
    truth = np.array([*field[:2], gradient[0, 0], gradient[0, 1], gradient[1, 1]])
    value = np.array([*decomposition.field_t, *decomposition.gradient_t_per_m])
    std = np.sqrt(
        np.concatenate([np.diag(decomposition.field_covariance_t2), np.diag(decomposition.gradient_covariance)])
    )
    return (value - truth) / std, truth


@pytest.mark.slow
@pytest.mark.parametrize("make_rig", [sim_rig, daqmx_rig], ids=["sim", "nidaqmx+scpi"])
def test_a_sweep_decomposes_within_two_sigma(make_rig):
    rig, device = make_rig(load_scenario("calibration_gradient"))
    assert rig.supply(SUPPLY_A).accepted
    outcome = rig.sweep(ANGLES_RAD, 2)
    assert outcome.ok, outcome.message
    decomposition = outcome.map.decomposition
    pull, truth = pulls(decomposition, device)
    assert truth[2] > 5e-3  # the supply's gradient is there: Gxx ≈ 9.8 mT/m at 0.5 A
    assert np.all(np.abs(pull) < 2.0), (pull, decomposition.report())
    rig.session.close()


@pytest.mark.slow
@pytest.mark.parametrize("make_rig", [sim_rig, daqmx_rig], ids=["sim", "nidaqmx+scpi"])
def test_a_calibration_recovers_the_probe(make_rig):
    scenario = load_scenario("calibration")
    rig, _ = make_rig(scenario)
    plan = CalibrationPlan(currents_a=(0.0, 1.0, 2.0, -1.0, -2.0), theta0_rad=(0.0, math.pi), repeats=1)
    outcome = rig.calibrate(plan)
    assert outcome.success and outcome.supply_at_zero, outcome.message
    nominal = load_scenario("helmholtz").probe  # the data sheet: moment, magnet mass, stop
    calibration = calibrate_probe(
        list(outcome.points),
        scenario_wirings(scenario),
        KnownConstants.of(nominal),
        "helmholtz",
        outcome.failed,
        nominal.lever_m,
    )
    truth = scenario.probe
    for name in ("spring_nm_per_rad", "inertia_kgm2"):
        error = (calibration.value(name) - getattr(truth, name)) / calibration.std(name)
        assert abs(error) < 3.0, (name, calibration.report())
    rig.session.close()
