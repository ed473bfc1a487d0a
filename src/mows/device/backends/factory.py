"""The driver's backend made from plain settings: the simulator of a scenario, a device on a
serial port, a recorded bag, or the paper's bench (the NI card and its SCPI field supply,
docs/hardware.md). :class:`BackendSettings` carries the driver's parameters of the same names
(docs/nodes.md); :func:`make_backend` builds the backend they choose. The bench alone is
:class:`BenchSettings` (``mows check-hardware`` opens it too, :func:`open_bench`), whose supply
cap is lowered to the driver's ``supply_current_cap_a`` by one rule,
:meth:`BenchSettings.supply_config`. The simulated bench, for a rehearsal without hardware, is
the same backend on NI's own package with only its lowest layer replaced (:func:`simulated_card`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import pathlib

from mows.device.backends.bag_backend import BagBackend
from mows.device.backends.daqmx_backend import DaqmxBackend, open_daqmx
from mows.device.backends.serial_backend import SerialBackend
from mows.device.backends.sim_backend import SimBackend
from mows.device.instruments.daq import PAPER_DEVICE_FILE, DaqDevice, load_daq_device
from mows.device.instruments.scpi import (
    PAPER_SUPPLY_FILE,
    SIMULATED_RESOURCE,
    SIMULATED_SUPPLY_FILE,
    ScpiSupply,
    ScpiSupplyConfig,
    load_supply_file,
    open_scpi_supply,
)
from mows.device.interface import Backend
from mows.device.serial.link import DEFAULT_BAUD, SerialLink
from mows.physics.coils import CurrentCap
from mows.sim.scenario import DEFAULT_SCENARIO, Scenario, load_scenario
from mows.sim.simulator import SimulatedDevice

SIMULATED_SCENARIO = "paper_largest_spacing"  # the coils both seen at the fluxgates (Fig. 2a)
SIMULATED_SUPPLY_SCENARIO = "calibration"  # lends its supply: the Pasco pair on the NGM202


@dataclasses.dataclass(frozen=True)
class BenchSettings:
    """The paper's bench: the NI card of ``daq_device_file`` and the SCPI supply of
    ``supply_file`` at the VISA address ``supply_resource`` ('' : no supply) through the PyVISA
    backend ``visa_library``, its current never above ``supply_current_cap_a`` (A).
    ``simulated``: the simulated bench (:func:`simulated_card`), its supply the NGM202 on
    pyvisa-sim at ``SIMULATED_RESOURCE`` (the only address it has)."""

    daq_device_file: str | pathlib.Path = PAPER_DEVICE_FILE
    supply_file: str | pathlib.Path = PAPER_SUPPLY_FILE
    supply_resource: str = ""
    visa_library: str = "@py"
    supply_current_cap_a: float = math.inf
    simulated: bool = False

    def __post_init__(self) -> None:
        if self.simulated and self.supply_resource not in ("", SIMULATED_RESOURCE):
            raise ValueError(
                f"supply_resource={self.supply_resource!r}: the simulated bench's supply is at "
                f"{SIMULATED_RESOURCE!r} ('' : the simulated bench without a supply)"
            )

    def supply_config(self) -> ScpiSupplyConfig:
        """The supply file, its cap lowered to ``supply_current_cap_a`` (never raised above the
        file's). ValueError naming the file and the key."""
        config = load_supply_file(self.supply_file)
        return dataclasses.replace(config, cap_a=min(config.cap_a, self.supply_current_cap_a))

    def open_supply(self) -> ScpiSupply | None:
        """The supply, prepared (:func:`mows.device.instruments.scpi.open_scpi_supply`); None
        without one."""
        if not self.supply_resource:
            return None
        library = f"{SIMULATED_SUPPLY_FILE}@sim" if self.simulated else self.visa_library
        return open_scpi_supply(self.supply_resource, self.supply_config(), library)


def open_bench(bench: BenchSettings, cap: CurrentCap) -> DaqmxBackend:
    """The backend on the card of ``bench`` with its supply; on the simulated bench, NI's package
    drives the simulated card until the backend is closed. A supply already opened is closed
    (switched off) again when the card cannot be opened, before the error goes on."""
    device = load_daq_device(bench.daq_device_file)
    supply = bench.open_supply()
    held = contextlib.ExitStack()
    try:
        if not bench.simulated:
            return open_daqmx(device, cap, supply, held)
        card = held.enter_context(simulated_card(device, supply).installed())
        return open_daqmx(device, cap, supply, held, turned=card.turn_probe)  # the operator turns its probe
    except BaseException:
        held.close()
        if supply is not None:
            supply.close()
        raise


def simulated_card(device: DaqDevice, supply: ScpiSupply | None):
    """The simulated card wired as ``device`` says, in wall-clock time, over the paper's
    largest-spacing scene with the Pasco pair on its field supply, driven by ``supply`` (the
    NGM202 on pyvisa-sim; None: no current)."""
    from mows.device.simulated.daqmx_card import SimulatedCard  # NI's package only when simulating

    scenario = load_scenario(SIMULATED_SCENARIO)
    return SimulatedCard(
        SimulatedDevice(scenario.replace(supply=load_scenario(SIMULATED_SUPPLY_SCENARIO).supply)),
        tuple(i.physical_channel for i in device.inputs),
        tuple(o.physical_channel for o in device.outputs),
        device.amplifier_v_per_a,
        device.inputs[0].sensitivity_v_per_t,
        supply_current_a=supply.resource.visalib.instruments[SIMULATED_RESOURCE].delivered_a if supply else None,
    )


@dataclasses.dataclass(frozen=True)
class BackendSettings:
    """Where the driver's blocks come from, in the driver's parameters of these names
    (docs/nodes.md): ``backend`` sim (``scenario`` with the stage at ``theta0_rad``, simulated in
    pieces of ``block_duration_s``; its supply capped at ``supply_current_cap_a``, slewing at
    ``supply_slew_a_per_s``), serial (``serial_port`` at ``baud``), bag (``bag_path`` replayed at
    ``bag_rate``) or nidaqmx (the bench: ``daq_device_file`` and, with ``supply`` scpi,
    ``supply_file`` at ``supply_resource``; '' the paper's files; ``daq_simulated``: the simulated
    bench instead, its supply at the simulated address). ``coil_setup``: the coils' setup, '' the
    scenario's. ``scene``: the scenario, read once when the settings are made (the coils' setup
    and tracking's device come from it whatever the backend); ValueError or OSError when it
    cannot be read."""

    backend: str = "sim"
    scenario: str = DEFAULT_SCENARIO
    coil_setup: str = ""
    theta0_rad: float = 0.0
    block_duration_s: float = 0.025
    serial_port: str = ""
    baud: int = DEFAULT_BAUD
    bag_path: str = ""
    bag_rate: float = 1.0
    supply: str = "device"
    supply_current_cap_a: float = 2.0
    supply_slew_a_per_s: float = 2.0
    daq_device_file: str = ""
    supply_file: str = ""
    supply_resource: str = ""
    visa_library: str = "@py"
    daq_simulated: bool = False
    scene: Scenario = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "scene", load_scenario(self.scenario))

    @property
    def simulated(self) -> bool:
        """Whether the device is simulated here (the sim backend, the simulated NI bench): the
        simulator's kernels are then compiled before it streams."""
        return self.backend == "sim" or self.daq_simulated

    def setup_name(self) -> str:
        """The coil setup that drives the coils: ``coil_setup``, or when it is '' the scenario's."""
        return self.coil_setup or self.scene.setup.name

    def tracking_scenario(self) -> Scenario:
        """The scenario whose device tracking mode follows; ValueError when the simulated scene
        has several probes (tracking retunes one probe's kicks)."""
        if self.backend == "sim" and len(self.scene.probes) > 1:
            raise ValueError(
                f"tracking=True: tracking follows one probe; scenario {self.scenario!r} has {len(self.scene.probes)}"
            )
        return self.scene


def make_backend(settings: BackendSettings, cap: CurrentCap) -> Backend:
    """The backend ``settings`` choose, its coils under ``cap``. ValueError (naming the setting)
    when it cannot be made, OSError (one line) when its device cannot be opened."""
    s = settings
    if s.supply == "scpi" and s.backend != "nidaqmx":
        raise ValueError(f"supply='scpi' goes with backend nidaqmx, not {s.backend!r} (its supply is the device's)")
    if s.daq_simulated and s.backend != "nidaqmx":
        raise ValueError(f"daq_simulated=True goes with backend nidaqmx, not {s.backend!r}")
    if s.backend == "sim":
        if s.coil_setup not in ("", s.scene.setup.name):
            raise ValueError(
                f"coil_setup={s.coil_setup!r} does not drive the coils of scenario "
                f"{s.scenario!r} ({s.scene.setup.name})"
            )
        # At rest with the stage at theta0_rad (each probe of a scene at its home orientation plus
        # it), its integrator compiled beforehand (mows.precompile, as the driver does: else the
        # first read compiles it while the stream waits); simulated in pieces of one block, so that
        # blocks come out evenly at the least cost per sample.
        device = SimulatedDevice(s.scene, theta0_rad=s.scene.stage_orientations_rad(s.theta0_rad))
        return SimBackend(
            device,
            cap,
            chunk_s=s.block_duration_s,
            supply_cap_a=s.supply_current_cap_a,
            supply_slew_a_per_s=s.supply_slew_a_per_s,
        )
    if s.backend == "serial":
        if not s.serial_port:
            raise ValueError("serial_port='' : backend serial needs the device's port")
        return SerialBackend(SerialLink(s.serial_port, s.baud).start(), cap)
    if s.backend == "bag":
        if not s.bag_path:
            raise ValueError("bag_path='' : backend bag needs the bag to replay")
        return BagBackend(s.bag_path, s.bag_rate)
    if s.backend != "nidaqmx":
        raise ValueError(f"backend={s.backend!r} is not one of sim, serial, bag, nidaqmx")
    if s.supply == "device":
        raise ValueError("supply='device' : the NI card has no supply of its own; use scpi or none")
    if s.supply == "scpi" and not s.supply_resource and not s.daq_simulated:
        raise ValueError("supply_resource='' : supply scpi needs the supply's VISA address")
    resource = s.supply_resource or (SIMULATED_RESOURCE if s.daq_simulated else "")
    bench = BenchSettings(
        s.daq_device_file or PAPER_DEVICE_FILE,
        s.supply_file or PAPER_SUPPLY_FILE,
        resource if s.supply == "scpi" else "",
        s.visa_library,
        s.supply_current_cap_a,
        s.daq_simulated,
    )
    return open_bench(bench, cap)
