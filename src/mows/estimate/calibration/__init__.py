"""Calibration from ring-downs in known fields: the zero-field frequency f00 from a known field
along the axis (``f00``: :class:`F00Calibration`), and a new probe's constants (``fit``:
:func:`calibrate_probe`, paper Fig. 3), with what that fit takes and gives (``constants``) and
its model of one ring-down (``model``).

May import: the rest of ``mows.estimate`` (the ring-down fit's types), ``mows.physics``,
``mows.records``.
"""
