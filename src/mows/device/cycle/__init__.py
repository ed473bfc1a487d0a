"""The measurement cycle as I/O-free state machines over device sample indices, fed samples,
command results and link changes, returning the commands to send and the events to publish.

``phases`` (the vocabulary: phases and their events, settings, a request, its plan and outcome,
the step the sequencer returns), ``sequencer`` (:class:`~mows.device.cycle.sequencer.CycleSequencer`:
the cycle of the probes of one stage, one probe a stage of one), ``excitation`` (each round's
plan of tones and what a group's excitation drives and announces), ``waits`` (what a running
cycle waits for and records), ``duty`` (the coils' duty-cycle limit), ``tone_groups`` (the groups
of a plan excited in turn, and the tones sized for a swing), ``tracking`` (tracking
mode's cycles, back to back) and ``tracking_plan`` (its kicks and ring-downs from the probe's
physics, and the drive's physics every planned cycle uses).

May import: ``mows.device.interface``, ``mows.device.clock``, ``mows.device.protocol``,
``mows.device.simulated``, ``mows.sim``, ``mows.physics``, ``mows.records``; not ``recording``,
``serial``, ``instruments``, ``backends`` or ``stream``.
"""
