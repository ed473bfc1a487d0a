"""From samples to numbers: ring-down windows cut from the block stream (``segments``), the
ring-down fit at the Cramér–Rao bound (``ringdown``: one or several probes ringing down
together in one window, and its kernels), the
field and gradient along the probe axis (``axis``), calibration from ring-downs in known fields
(``calibration``: f00, and a new probe's constants), and the estimator's flow from messages to
estimates (``stream``).

May import: ``mows.physics``, ``mows.records``. Independent of ``mows.device`` and
``mows.sim``: it sees samples, never where they came from.
"""
