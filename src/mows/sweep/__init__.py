"""Rotation sweeps: (θ0, Δf) points of many orientations decomposed into in-plane field and
gradient (``decompose``), the ring-downs of one sweep as they arrive (``record``), a sweep
run as an I/O-free state machine (``runner``), and the supply sweep that calibrates a probe
(``calibration_schedule``).

May import: ``mows.estimate``, ``mows.physics``, ``mows.records``.
"""
