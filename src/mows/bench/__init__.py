"""Benchmarks behind ``mows bench``: each module has ``run(...) -> dict`` of printed figures;
``rig`` runs the driver's cycle and the estimator's fit on the simulator in device time.

Figures only: nothing here asserts a timing (tests never depend on the machine's speed).
"""
