"""The serial wire format of the device link (docs/serial_protocol.md), as bytes and nothing
else: the frame types' payloads (``payloads``: one ``Body`` class per type, and
:class:`~mows.device.protocol.payloads.DeviceInfo`, what every backend says about its device)
and the frame codec with its incremental decoder (``framing``). No I/O, no clock.

May import: numpy and the standard library; nothing else of ``mows``.
"""
