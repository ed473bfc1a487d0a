"""The simulated world: scenario files (``scenario``, its sections
``sections`` and YAML reading ``scenario_yaml``) and the time-domain simulation of the
whole measurement, sample by sample like the hardware: the device (``simulator``), its numba
dynamics kernels (``kernel``) and noise stream (``noise``), one measurement cycle (``cycle``);
several probes ringing down together in each other's fields (``multiprobe``).

May import: ``mows.physics``, ``mows.records``. Never the estimator: a simulation knows the
truth and must not borrow the fit's assumptions.
"""
