"""The probe calibration as the rig runs it: supply steps × orientations × cycles as an I/O-free
state machine (``schedule``: :class:`CalibrationSchedule`), the calibrator's goals around it
(``run``: :class:`CalibrationRun`, :class:`ProbeCalibrator`), and the schedule run on the
simulated device in device time (``simulated``: :func:`simulate_calibration`).

May import: the rest of ``mows.sweep`` (the runner's cycle answers and turn prompts),
``mows.device`` (the device-time loop), ``mows.estimate``, ``mows.physics``, ``mows.records``.
"""
