"""QoS profiles of the MOWS graph, named by the kind of data they carry."""

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)


def _keep_last(depth: int, reliability, durability) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability, durability=durability)


# Raw blocks: the sensor-data pattern (best effort, volatile: a late sample is worth less
# than the next one), with a deeper history than qos_profile_sensor_data's 5. At 40 blocks/s
# five blocks are 125 ms, and with shared-memory delivery the writer's history is the buffer:
# a consumer busy fitting on a loaded machine would lose blocks that were never late.
STREAM_QOS = _keep_last(64, qos_profile_sensor_data.reliability, qos_profile_sensor_data.durability)

# Excitation phase changes: every one matters, and a subscriber that joins late learns the
# recent ones: the estimator hears a ring-down announced before discovery matched it (a
# RESULT_QOS subscriber, volatile, is compatible with it; a volatile publisher is not).
EXCITATION_QOS = _keep_last(100, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)

# Per-event results (excitation states, ring-down fits, field estimates): low rate, and a
# consumer that counts them (the mapper waits for every repeat) must not lose one.
RESULT_QOS = _keep_last(100, ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)


def maps_qos(maps: int) -> QoSProfile:
    """Maps that a subscriber joining later still gets: the latest ``maps`` of them (a sweep of
    several probes publishes one decomposition per probe)."""
    return _keep_last(maps, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)


# Maps (sweep decompositions, model reports, field maps): the latest one.
MAP_QOS = maps_qos(1)

# Joint states (the rotation stage's angle, with every block): reliable and volatile like a
# robot's /joint_states, so that robot_state_publisher (either reliability) takes them.
JOINT_QOS = _keep_last(10, ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)
