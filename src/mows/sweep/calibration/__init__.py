"""The probe calibration as the rig runs it: supply steps × orientations × cycles as an I/O-free
state machine (``schedule``: :class:`CalibrationSchedule`) and the calibrator's goals around it
(``run``: :class:`CalibrationRun`, :class:`ProbeCalibrator`).

May import: the rest of ``mows.sweep`` (the runner's cycle answers and turn prompts),
``mows.estimate``, ``mows.physics``, ``mows.records``.
"""
