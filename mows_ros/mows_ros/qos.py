"""QoS profiles of the MOWS graph, named by the kind of data they carry."""
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

# Raw blocks and per-ring-down results: a late sample is worth less than the next one.
STREAM_QOS = qos_profile_sensor_data

# A consumer of the raw stream that does real work per block (the estimator fits while
# blocks keep coming): best effort like the stream, but a deeper queue rides out a fit.
STREAM_CONSUMER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=64,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)

# Per-event results (excitation states, ring-down fits, field estimates): low rate, and a
# consumer that counts them (the mapper waits for every repeat) must not lose one.
RESULT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

# Maps (sweep decompositions): a subscriber that joins later still gets the latest one.
MAP_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
