"""The simulated world: scenario files (``scenario``, its sections
``sections`` and YAML reading ``scenario_yaml``) and the time-domain simulation of the
whole measurement, sample by sample like the hardware: the device (``simulator``, every probe
of its scene, one or several in each other's fields), what it returns (``readings``), its numba
dynamics kernels (``kernel``) and noise stream (``noise``); the navigation system of workspace
maps (``navigation``).

May import: ``mows.physics``, ``mows.records``. Never the estimator: a simulation knows the
truth and must not borrow the fit's assumptions.
"""
