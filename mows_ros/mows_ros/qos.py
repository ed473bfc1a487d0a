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

# Maps (sweep decompositions): a subscriber that joins later still gets the latest one.
MAP_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
