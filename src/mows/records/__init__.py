"""Records every stage passes on: device-clock stamps in integer nanoseconds (``stamps``).

The bottom layer: imports numpy and the standard library only, nothing else of ``mows``.
"""
