"""Records every stage passes on: device-clock stamps in integer nanoseconds (``stamps``),
the rule for files a command writes (``files``: never over an input, never half-written), and
for numbers written as JSON (``json_numbers``: what is not finite is null).

The bottom layer: imports numpy and the standard library only, nothing else of ``mows``.
"""
