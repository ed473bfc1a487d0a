"""The driver's session, without ROS: one backend polled by one streaming thread, with cycles,
the emergency stop and supply currents requested from other threads, and coils driven only
while armed (``session``: :class:`~mows.device.stream.session.DeviceSession`). Beside it what
the session owns: the stream cut into published blocks with gaps counted (``blocks``), the
sample rate received (``rate``) and the static-field supply's ramps from sent to reached
(``supply_ramps``). Beside the session, its counterpart on the simulator in device time
(``device_time``: :class:`~mows.device.stream.device_time.DeviceTimeLoop`, the sequencer's cycles
without threads, for the benchmarks and the simulated calibration), and its cycles' ring-downs
recorded with the simulation's truth (``simulated_cycle``: ``mows sim``, the physics tests).

May import: the device packages under it (``cycle``, ``recording``, ``serial``, ``instruments``,
``simulated``, ``interface``, ``clock``, ``protocol``), ``mows.sim``, ``mows.physics``,
``mows.records``; not ``backends``: the driver node hands the session its backend.
"""
