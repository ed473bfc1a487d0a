"""The driver's devices, each a :class:`mows.device.interface.Backend`: the simulator in this
process (``sim_backend``, one probe or a scene of several), a device on a serial port
(``serial_backend``), a recorded bag replayed (``bag_backend``), and the paper's bench on an NI
card with an SCPI supply (``daqmx_backend``; its card's tasks: ``daqmx_tasks``; its supply's
I/O on a thread of its own: ``bench_supply``); the one the driver's settings choose, made by
``factory`` (:func:`~mows.device.backends.factory.make_backend`).

May import: the device packages under it (``cycle``, ``recording``, ``serial``, ``instruments``,
``simulated``, ``interface``, ``clock``, ``protocol``), ``mows.sim``, ``mows.physics``,
``mows.records``; not ``stream``.
"""
