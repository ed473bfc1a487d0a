"""The MOWS calibrator node: a new probe's constants from supply sweeps (docs/calibration.md)."""
