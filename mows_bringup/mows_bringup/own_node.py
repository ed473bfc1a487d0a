"""A node in a ROS context of its own, with an executor to spin it: for the helpers a program
runs beside its own work (the lifecycle client of ``mows-graph``, the operator's confirmation).
A program with a context of its own (mows-demo) is not disturbed, and no signal handler is
installed: the program's own stay."""

from collections.abc import Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions


class OwnNode:
    """``node``, named ``name``, under ``ros_args`` (a namespace given there applies to the
    names it uses), in a context that ``close`` shuts down."""

    def __init__(self, program: str, name: str, ros_args: Sequence[str]):
        self._context = Context()
        arguments = [program, "--ros-args", *ros_args]
        rclpy.init(args=arguments, context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self._context)
        self.executor = SingleThreadedExecutor(context=self._context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self._context.try_shutdown()
