"""Records every stage passes on: device-clock stamps in integer nanoseconds (``stamps``),
and the rule for files a command writes (``files``: never over an input, never half-written).

The bottom layer: imports numpy and the standard library only, nothing else of ``mows``.
"""
