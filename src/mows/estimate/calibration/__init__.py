"""Calibration from ring-downs in known fields: the zero-field frequency f00 from a known field
along the axis (``f00``: :class:`F00Calibration`), and a new probe's constants
(``fit_constants``: :func:`calibrate_probe`, paper Fig. 3), with what that fit takes and gives
(``constants``), its model of one ring-down (``predicted``), the constants derived from its
parameters (``derived``) and which way each wiring is connected (``polarity``).

May import: the rest of ``mows.estimate`` (the ring-down fit's types), ``mows.physics``,
``mows.records``.
"""
