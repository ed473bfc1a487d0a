"""The lab's input: measurement tables and where they come from.

``table`` (:class:`MeasurementTable`, its columns, validation and errors), ``folds`` (rows held
out a configuration at a time for cross-validation), ``reference`` (the
reference field of a static source as table columns), ``probes`` (the constants of a table's
probes and their neighbours' field at each row), ``readers`` (:func:`load_table`: CSV, the
project's bags, rotation sweeps), ``scale`` (a table's frequencies and reference held against
its probes: a column in the wrong unit), ``ringdowns`` (a driver's bag's ring-downs cut and
fitted as the estimator does), ``calibration_table`` (the probe calibration's table, written
and read back), ``truth`` (a decomposition against its simulated scene's truth, with pulls) and
``synthetic`` (tables from independent physics and from the simulator and estimator, the lab's
test data).

May import: ``mows.lab.progress`` and the core below the lab (``mows.sweep``, ``mows.estimate``,
``mows.device``, ``mows.sim``, ``mows.physics``, ``mows.records``); no other lab package.
"""
