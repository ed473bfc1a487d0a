"""rosbag2 recordings (MCAP storage) without a ROS install: written and read with ``rosbags``
in the layout of Jazzy's ``ros2 bag`` (``bags``), and a recording that was never closed
salvaged chunk by chunk into a closed bag (``bag_repair``, ``mows bag repair``).

May import: ``rosbags``, and ``mows.device.interface``, ``mows.device.clock``,
``mows.device.protocol``, ``mows.device.simulated``, ``mows.sim``, ``mows.physics``,
``mows.records``; not ``cycle``, ``serial``, ``instruments``, ``backends`` or ``stream``.
"""
