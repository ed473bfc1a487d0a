"""Rotation sweeps: (θ0, Δf) points of many orientations decomposed into in-plane field and
gradient (``decompose``: the fit of the sweep's model, ``shift_model``, reporting a
``decomposition``), the ring-downs of one sweep as they arrive (``record``), one or several
probes' shares of a sweep decomposed, each with its neighbours' fields (``probes``), a sweep run
as an I/O-free state machine (``runner``) and what the mapper publishes at its end
(``publication``), the supply sweep that calibrates a probe, the calibrator's goals around it
and the same sweep on the simulated device (``calibration``), the measurement cycle from the
probe's physics and the paper's protocol beside it (``fast_cycle``), and the adaptive choice of
orientations and repeats for a target precision (``planner``).

May import: ``mows.device`` (the cycle's settings and the drive's physics, the device-time loop),
``mows.estimate``, ``mows.physics``, ``mows.records``.
"""
