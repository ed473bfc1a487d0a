"""The device edge: what a device is to the driver (``interface``), the serial wire format
(``payloads``, ``framing``), its sample clock (``clock``), the simulated device with commands
at exact sample indices (``scheduled``), the device emulator on a pseudo-terminal (``emulator``),
the serial client (``serial_link``), the driver's backends over all of them (``sim_backend``,
``serial_backend``, ``bag_backend``, and the paper's bench: ``daq``, ``daqmx_backend``, ``scpi``,
``simulated_daqmx``), the measurement cycle (``cycle``, ``cycle_waits``,
``duty``), tracking mode's chain of cycles (``tracking``), the block stream (``blocks``,
``session``) and rosbag2 recordings (``bags``).

May import: ``mows.sim``, ``mows.physics``, ``mows.records``. Independent of
``mows.estimate``: a cycle that retunes is handed its fit function.
"""
