"""The simulator (:mod:`mows.sim`) dressed as hardware, for the sim backend, the device
emulator, the bench and the tests: a device whose commands take effect at chosen sample indices
(``scheduled``: :class:`~mows.device.simulated.scheduled.ScheduledDevice`, one probe or a scene
of several on one stage, with the current cap and the static-field supply's ramps), and the
paper's NI card in wall-clock time under NI's own ``nidaqmx``, its C library's interpreter
replaced (``daqmx_card``: :class:`~mows.device.simulated.daqmx_card.SimulatedCard`; the
interpreter on it, ``daqmx_interpreter``), and the field supply under PyVISA, pyvisa-sim's library
given a supply's latency, settling, read-back noise, error queue and faults (``visa_supply``).

May import: ``mows.sim``, ``mows.physics``, ``mows.records``, NI's ``nidaqmx`` (``daqmx_card``,
``daqmx_interpreter``),
``pyvisa_sim`` (``visa_supply``), and
``mows.device.interface``, ``mows.device.clock``, ``mows.device.protocol``; no other device package.
"""
