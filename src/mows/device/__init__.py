"""The device edge: what the driver talks to, from the bytes on a serial line up to the session
the driver node runs. Sub-packages in the order the data flows, each importing only those after
it in this list (``pyproject.toml``, import-linter); the two modules beside them, ``interface``
and ``clock``, sit under all but ``protocol``.

1. ``stream``: the driver's session over one backend (cycles, the emergency stop, the supply's
   ramps, arming), the blocks it publishes and the sample rate it receives; beside it the same
   sequencer's cycles on the simulator in device time.
   ``backends``: the driver's devices (``sim``, ``serial``, ``bag``, ``nidaqmx``), each a
   :class:`~mows.device.interface.Backend`. The two never import each other: the driver node
   hands a backend to a session.
2. ``cycle``: the measurement cycle and its kin as I/O-free state machines on the device clock
   (one probe, several probes' tones, tracking mode, the duty-cycle limit). ``recording``:
   rosbag2 recordings and their repair. ``serial``: both ends of the serial link (the host's
   link, the device emulator). ``instruments``: the paper's bench (the NI card's waveforms,
   the SCPI supply, the step-by-step hardware check, the device files). These four are
   independent of each other.
3. ``simulated``: the simulator dressed as hardware (commands at exact samples; NI's Task API).
4. ``interface``: what a device is to the driver (commands, results, link events, ``Backend``);
   ``clock``: the device's sample clock.
5. ``protocol``: the serial wire format (docs/serial_protocol.md): payloads and frames.

May import: ``mows.sim``, ``mows.physics``, ``mows.records``. Independent of
``mows.estimate``: a cycle that retunes is handed its fit function.
"""
