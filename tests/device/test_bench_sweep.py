"""A rotation sweep and a probe calibration on the paper's bench backends (the NI card through
NI's ``nidaqmx`` on the simulated card, the NGM202 through PyVISA on pyvisa-sim), run
by the core's state machines as the mapper and the calibrator run them.

Requirement (the bench's Done-when): the sweep on the DAQmx and SCPI backends decomposes within
2σ of the true field and gradient, as the same sweep on the simulator backend does; a calibration
on each backend combination recovers the probe's constants. The scene: the calibration probe in
the Helmholtz setup with the Pasco pair anti-parallel on the supply at 0.5 A (Gxx ≈ +9.8 mT/m,
the Earth's field); six orientations, two ring-downs each.

The NGM202 is unipolar: on it the calibration runs a non-negative plan (0, 1 and 2 A at θ0 = 0° and
180°, the field's other sign from the turn: every other current of the product's unipolar plan,
whose 0.5 A steps cost 40 s more of the card's wall clock) and recovers f00, β0, kM, J and l
within 2σ each,
with the lever check of the anti-parallel wiring; the paper's plan with negative currents is
refused before the supply is set at all. (The rig's noise is seeded: the test is one draw. The
same two calibrations on the simulator backend over 40 seeds: the pulls' sd 0.84–0.92 per
constant, 6 of 240 beyond 2σ, the largest 2.44; with the five currents 0.72–1.16, 10 of 240, the
largest 3.40.)
"""

import dataclasses
import math

import numpy as np
import pytest

from device.bench_runs import BenchRig
from mows.device.backends.daqmx_backend import open_daqmx
from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleSettings
from mows.device.instruments.daq import load_daq_device
from mows.device.instruments.scpi import SIMULATED_RESOURCE, SIMULATED_SUPPLY_FILE, load_supply_file, open_scpi_supply
from mows.device.simulated.daqmx_card import SimulatedCard
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.calibration.constants import CalibrationError, KnownConstants
from mows.estimate.calibration.fit_constants import calibrate_probe
from mows.estimate.ringdown import fit_tuning
from mows.lab import reference_at
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice
from mows.sweep.calibration.schedule import (
    GRADIENT_WIRING,
    PAPER_CURRENTS_A,
    UNIPOLAR_CURRENTS_A,
    CalibrationPlan,
    scenario_wirings,
)

SETTINGS = CycleSettings(excite_s=0.5, ringdown_s=0.5, gap_s=0.2, repeats=2, tuning_steps=1, turn_settle_s=0.5)
ANGLES_RAD = tuple(np.radians(np.arange(0.0, 360.0, 60.0)))
SUPPLY_A = 0.5
CAP = CurrentCap(10.0)


def sim_rig(scenario, installed=None):
    backend = SimBackend(SimulatedDevice(scenario), CAP, paced=False, supply_cap_a=2.0, supply_slew_a_per_s=2.0)
    return BenchRig(session(backend, scenario), scenario), backend.device.device


def daqmx_rig(scenario, installed):
    supply = open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(), f"{SIMULATED_SUPPLY_FILE}@sim")
    properties = supply.resource.visalib.devices[SIMULATED_RESOURCE]._properties
    card = installed(
        SimulatedCard(
            SimulatedDevice(scenario),
            supply_current_a=lambda: properties["current"].get_value() * properties["output"].get_value(),
        )
    )
    # The rig decomposes between reads (the driver's stream never waits for the mapper): the
    # longest watchdog a bench file may give; the card's 10 s input buffer bounds the pause anyway.
    device = dataclasses.replace(load_daq_device(), watchdog_s=60.0)
    backend = open_daqmx(device, CAP, supply)
    return BenchRig(session(backend, scenario), scenario, card.turn_probe, manual=True), card.device


@pytest.fixture
def closing():
    """Closes each session handed to it when the test ends, passed or failed. The simulated
    supplies of one process are one pyvisa-sim instrument: a bench left open would switch the
    next test's supply off (its watchdog, once nobody reads it)."""
    sessions: list = []
    yield sessions.append
    for opened in sessions:
        opened.close()


def session(backend, scenario):
    config = SessionConfig(0.025, SETTINGS, scenario.setup, CAP, scenario.probe.f00_hz, fit_tuning)
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
def test_a_sweep_decomposes_within_two_sigma(make_rig, installed, closing):
    rig, device = make_rig(load_scenario("calibration_gradient"), installed)
    closing(rig.session)
    assert rig.supply(SUPPLY_A).accepted
    outcome = rig.sweep(ANGLES_RAD, 2)
    assert outcome.ok, outcome.message
    decomposition = outcome.map.decomposition
    pull, truth = pulls(decomposition, device)
    assert truth[2] > 5e-3  # the supply's gradient is there: Gxx ≈ 9.8 mT/m at 0.5 A
    assert np.all(np.abs(pull) < 2.0), (pull, decomposition.report())
    rig.session.close()


def calibrated(outcomes, wirings):
    """The constants from the outcomes' points, the nominal probe's data sheet as the known part."""
    nominal = load_scenario("helmholtz").probe  # the data sheet: moment, magnet mass, stop
    points = [p for outcome in outcomes for p in outcome.points]
    failed = {key: n for outcome in outcomes for key, n in outcome.failed.items()}
    return calibrate_probe(points, wirings, KnownConstants.of(nominal), "helmholtz", failed, nominal.lever_m)


def calibration_pulls(calibration, truth) -> dict:
    """(calibrated − true)/σ by constant. ``lever_m`` is √(J/a) by definition (a point magnet on a
    light lever): its truth is that of the true J, which the scenario's lever (the one the
    simulated gradient acts on, ``gradient_lever_m``'s truth) gives to five digits only."""
    true = {
        "f00_hz": truth.f00_hz,
        "beta0_hz_per_t": truth.beta0_hz_per_t,
        "spring_nm_per_rad": truth.spring_nm_per_rad,
        "inertia_kgm2": truth.inertia_kgm2,
        "lever_m": math.sqrt(truth.inertia_kgm2 / truth.magnet_mass_kg),
        "gradient_lever_m": truth.lever_m,
    }
    return {n: (calibration.value(n) - v) / calibration.std(n) for n, v in true.items() if n in calibration.names}


@pytest.mark.slow
def test_a_calibration_on_the_simulator_backend_recovers_the_probe():
    scenario = load_scenario("calibration")
    rig, _ = sim_rig(scenario)
    plan = CalibrationPlan(currents_a=(0.0, 1.0, 2.0, -1.0, -2.0), theta0_rad=(0.0, math.pi), repeats=1)
    outcome = rig.calibrate(plan)
    assert outcome.success and outcome.supply_at_zero, outcome.message
    calibration = calibrated([outcome], scenario_wirings(scenario))
    pull = calibration_pulls(calibration, scenario.probe)
    for name in ("spring_nm_per_rad", "inertia_kgm2"):
        assert abs(pull[name]) < 3.0, (name, calibration.report())
    rig.session.close()


@pytest.mark.slow
def test_a_calibration_on_the_unipolar_supply_recovers_the_probe_with_the_lever_check(installed, closing):
    scenario, gradient = load_scenario("calibration"), load_scenario("calibration_gradient")
    outcomes = []
    for scene, wiring in ((scenario, "helmholtz"), (gradient, GRADIENT_WIRING)):
        rig, _ = daqmx_rig(scene, installed)
        closing(rig.session)
        limits = rig.session.backend.supply_limits
        plan = CalibrationPlan(UNIPOLAR_CURRENTS_A[::2], (0.0, math.pi), wiring=wiring)
        plan.check_supply(limits.min_current_a, limits.cap_a)  # as the calibrator checks a goal
        outcomes.append(rig.calibrate(plan))
        rig.session.close()
        assert outcomes[-1].success and outcomes[-1].supply_at_zero, outcomes[-1].message
    assert min(p.supply_current_a for outcome in outcomes for p in outcome.points) == 0.0
    calibration = calibrated(outcomes, scenario_wirings(scenario, gradient))
    pull = calibration_pulls(calibration, scenario.probe)
    assert set(pull) == {"f00_hz", "beta0_hz_per_t", "spring_nm_per_rad", "inertia_kgm2", "lever_m", "gradient_lever_m"}
    assert all(abs(p) < 2.0 for p in pull.values()), (pull, calibration.report())
    check = [note for note in calibration.notes if note.startswith("lever check")]
    assert check and "σ apart" in check[0], calibration.notes
    # θ0 + 180° is what gives the field's other sign: one orientation alone leaves f00 undetermined.
    at_zero_deg = [dataclasses.replace(o, points=tuple(p for p in o.points if p.theta0_rad == 0.0)) for o in outcomes]
    with pytest.raises(CalibrationError, match="fields of one sign only"):
        calibrated(at_zero_deg[:1], scenario_wirings(scenario))


def test_the_paper_plan_is_refused_up_front_on_the_unipolar_supply(installed, closing):
    rig, _ = daqmx_rig(load_scenario("calibration"), installed)
    closing(rig.session)
    supply = rig.session.backend.supply
    writes = supply.writes
    limits = rig.session.backend.supply_limits
    with pytest.raises(ValueError, match=r"-0\.5 A of the plan is outside the supply's range 0 … \+2 A.*θ0 \+ 180°"):
        CalibrationPlan(PAPER_CURRENTS_A).check_supply(limits.min_current_a, limits.cap_a)
    with pytest.raises(ValueError, match=r"-0\.5 A is outside the supply's range 0 … \+2 A \(unipolar\)"):
        rig.session.set_field_current(-0.5, lambda result: None)
    assert supply.writes == writes  # nothing reached the supply
    rig.session.close()
