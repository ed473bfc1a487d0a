"""The device side of MOWS: what a device is to the driver (``interface``), its sample clock
(``clock``), the simulated device with commands at exact sample indices (``scheduled``), the
device emulator on a pseudo-terminal (``emulator``), the serial client (``serial_link``) and
the driver's backends over all of them (``backends``)."""
