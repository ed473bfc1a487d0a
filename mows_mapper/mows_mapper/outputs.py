"""The mapper's maps: what :func:`mows.sweep.publication.publication` says to publish at a
sweep's end, built (:mod:`mows_mapper.messages`) and published in order.

Each decomposition goes on ``mows/sweep`` (transient local, one kept per probe), then the field
map of several probes on ``mows/field_map``; the model lab's report follows on
``mows/model_report`` once the node has it.
"""

from mows_msgs.msg import FieldMap, ModelReport, SweepDecomposition
from rclpy.node import Node

from mows.sweep.publication import Publication
from mows_mapper.messages import field_map_msg, model_report_msg, publication_msgs
from mows_ros.qos import MAP_QOS, maps_qos


class MapperOutputs:
    """The mapper's publishers on ``node``, for sweeps of ``probes`` probes (1 for one)."""

    def __init__(self, node: Node, probes: int):
        self._logger = node.get_logger()
        self.sweep = node.create_publisher(SweepDecomposition, "mows/sweep", maps_qos(max(1, probes)))
        self.report = node.create_publisher(ModelReport, "mows/model_report", MAP_QOS)
        self.field_map = node.create_publisher(FieldMap, "mows/field_map", MAP_QOS)

    def publish(self, plan: Publication, frame_id: str, summary: str) -> list[SweepDecomposition]:
        """``plan``'s decompositions and field map, logged with ``summary`` (the decomposition's
        report); returns the decompositions sent."""
        decompositions = publication_msgs(plan, frame_id)
        for msg in decompositions:
            self.sweep.publish(msg)
        if plan.field_map:
            self.field_map.publish(field_map_msg(decompositions, plan.field_map, frame_id))
        if plan.sweeps:
            self._logger.info(plan.summary(summary))
        return decompositions

    def publish_report(self, report, sweep: SweepDecomposition) -> None:
        """The model lab's ``report`` on the published ``sweep``, with its header."""
        self.report.publish(model_report_msg(report, sweep.header, sweep.sweep_id))
