"""The paper's bench, apart from the backend that drives it (:mod:`mows.device.backends.daqmx_backend`,
docs/hardware.md): the NI card's channels, waveforms and inputs as plain functions over arrays
(``daq``), the SCPI field supply's command set and PyVISA edge (``scpi``), its ramps on the sample
clock (``supply_schedule``), the
step-by-step check of a bench before measuring on it (``hardware_check``), and the device
files in ``hardware/`` (the card, the R&S NGM202 supply, its pyvisa-sim instrument).

May import: ``mows.device.interface``, ``mows.device.clock``, ``mows.device.protocol``,
``mows.device.simulated``, ``mows.sim``, ``mows.physics``, ``mows.records``; not ``cycle``,
``recording``, ``serial``, ``backends`` or ``stream``.
"""
