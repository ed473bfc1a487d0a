"""From samples to numbers: ring-down windows cut from the block stream (``segments``), the
ring-down fit at the Cramér–Rao bound (``ringdown``, kernels in ``ringdown_model``), the
field and gradient along the probe axis (``axis``), and f00 calibrated from ring-downs in a
known field (``calibration``).

May import: ``mows.physics``, ``mows.records``. Independent of ``mows.device`` and
``mows.sim``: it sees samples, never where they came from.
"""
