"""Both ends of the serial link (docs/serial_protocol.md): the host's end with reconnection and
heartbeats (``link``: :class:`~mows.device.serial.link.SerialLink`) and the device emulator on a
pseudo-terminal, backed by the simulator (``emulator``:
``python -m mows.device.serial.emulator --link PATH``). The driver's backend over the link is
:mod:`mows.device.backends.serial_backend`.

May import: ``mows.device.protocol``, ``mows.device.interface``, ``mows.device.clock``,
``mows.device.simulated`` (the emulator's device), ``mows.sim``, ``mows.physics``,
``mows.records``; not ``cycle``, ``recording``, ``instruments``, ``backends`` or ``stream``.
"""
