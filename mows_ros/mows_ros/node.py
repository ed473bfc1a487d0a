"""The base of every MOWS node: a managed (lifecycle) node with its parameter table declared
and its health, lifecycle state included, on /diagnostics.

A managed node (ROS 2 node lifecycle, ``lifecycle_msgs``) starts ``unconfigured``;
``configure`` makes it ``inactive``, ``activate`` ``active``, ``deactivate`` inactive again,
``cleanup`` unconfigured, and ``shutdown`` ``finalized`` from any of them. A supervisor asks
for transitions through the services ``<node>/change_state`` and ``<node>/get_state``
(``ros2 lifecycle set /driver configure``); mows-graph does it for the whole graph, and a node
started with ``--autostart`` (``mows_ros.process``) does it for itself.

A subclass states only what its transitions do, by overriding the hooks ``configure`` (load
and check what it needs: a ValueError or OSError refuses, with its reason, ``cleanup``
releases what it took and the node stays unconfigured), ``activate``, ``deactivate`` and
``cleanup`` (release what ``configure`` took). Any other exception in a hook is the error
path: ``cleanup`` runs (so it must cope
with a ``configure`` that stopped half way), the node is unconfigured again and
/diagnostics reports the error until the next transition succeeds. Parameters, services and
/diagnostics exist in every state; what a node does only when active is its own to gate
(:meth:`MowsNode.when_active`, :meth:`MowsNode.inactive_reason`).
"""

import sys
import traceback
from collections.abc import Callable, Sequence

from diagnostic_msgs.msg import DiagnosticStatus
from lifecycle_msgs.srv import ChangeState
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

import mows
from mows_ros.answers import answering_when_heard
from mows_ros.diagnostics import DiagnosticsPublisher, Health
from mows_ros.params import (
    ROS_OWN,
    ParamSpec,
    declare_parameters,
    parameter_values,
    prefixed_overrides,
    unknown_parameter,
)
from mows_ros.wall import steady_timer

UNCONFIGURED, INACTIVE, ACTIVE, FINALIZED = "unconfigured", "inactive", "active", "finalized"
REFUSALS = (ValueError, OSError)  # what configure and activate refuse with: a FAILURE, not an error
GRAPH_NODE_NAMES = ("driver", "estimator", "mapper", "calibrator", "viz")  # mows_bringup.nodes.NODES, in order, and VIZ


class MowsNode(LifecycleNode):
    """A managed node named ``name`` with the parameters of ``table``.

    Subclasses translate between ROS and ``mows``, override the transition hooks, and override
    ``health`` to report what they are doing; the default reports that the node is up, with its
    parameters. /diagnostics adds the lifecycle state.
    """

    def __init__(self, name: str, table: Sequence[ParamSpec]):
        super().__init__(name)
        for service in self.services:  # the lifecycle services, which rclpy makes without create_service
            answering_when_heard(service, self.get_logger().warning, self.every)
        self.parameter_table = tuple(table)
        # ``-p driver:name:=value`` in a namespace, which rcl drops (the process's own command line)
        prefixed = prefixed_overrides(self.get_name(), sys.argv, GRAPH_NODE_NAMES)
        self._parameter_overrides.update(prefixed)
        # rclpy declared its own (use_sim_time) before the overrides above could reach them.
        self.set_parameters([value for name, value in prefixed.items() if name in ROS_OWN and self.has_parameter(name)])
        declare_parameters(self, self.parameter_table)
        self.lifecycle_state = UNCONFIGURED
        self.lifecycle_problem = ""  # why the last transition failed; '' once one succeeds
        change_state = self._service_change_state
        change_state.callback = self._refusing_unknown_transitions(change_state.callback)
        self.diagnostics = DiagnosticsPublisher(self, self._report)
        self.get_logger().info("up: " + ", ".join(f"{k}={v!r}" for k, v in parameter_values(self, table).items()))

    def create_service(self, *args, **kwargs):
        """rclpy's, with answers sent once the client is discovered (:mod:`mows_ros.answers`)."""
        return answering_when_heard(super().create_service(*args, **kwargs), self.get_logger().warning, self.every)

    def every(self, period_s: float, callback: Callable[[], None]) -> Callable[[], None]:
        """``callback`` every ``period_s`` on the steady clock (whatever use_sim_time says) until
        the function returned is called."""
        timer = steady_timer(self, period_s, callback)
        return lambda: self.destroy_timer(timer)

    # --- the hooks a node overrides ----------------------------------------------------------
    def configure(self) -> None:
        """Load and check what the node needs (ValueError or OSError: refused, with the reason)."""

    def activate(self) -> None:
        """Begin the node's work."""

    def deactivate(self) -> None:
        """Stop the node's work; it keeps what ``configure`` loaded."""

    def cleanup(self) -> None:
        """Release what ``configure`` took, whatever state it left (also the error path)."""

    def set_parameters_atomically(self, parameter_list) -> SetParametersResult:
        """rclpy's, with a name the node does not have refused with the nearest it has
        (``ros2 param set``), instead of rclpy's bare "undeclared parameter(s)"."""
        for parameter in parameter_list:
            if not self.has_parameter(parameter.name):
                return SetParametersResult(
                    successful=False, reason=unknown_parameter(self, parameter.name, self.parameter_table)
                )
        return super().set_parameters_atomically(parameter_list)

    # --- what a node asks of its state -------------------------------------------------------
    @property
    def active(self) -> bool:
        return self.lifecycle_state == ACTIVE

    def inactive_reason(self) -> str | None:
        """Why the node refuses a request now (None when it is active)."""
        if self.active:
            return None
        return f"the {self.get_name()} node is {self.lifecycle_state}: it serves requests only when active"

    def when_active(self, callback: Callable) -> Callable:
        """``callback`` for a subscription: messages are taken only while the node is active."""

        def take(message) -> None:
            if self.active:
                callback(message)

        return take

    def start_active(self) -> str | None:
        """Configure and activate this node (``--autostart``); why not, or None when active."""
        for trigger in (self.trigger_configure, self.trigger_activate):
            if trigger() != TransitionCallbackReturn.SUCCESS:
                return self.lifecycle_problem
        return None

    # --- the transitions ---------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        done = self._transition("configure", self.configure, INACTIVE, REFUSALS)
        if done == TransitionCallbackReturn.FAILURE:
            self.cleanup()  # what a configure refused half way took is released
        return done

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        done = self._transition("activate", self.activate, ACTIVE, REFUSALS)
        return super().on_activate(state) if done == TransitionCallbackReturn.SUCCESS else done

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        done = self._transition("deactivate", self.deactivate, INACTIVE)
        return super().on_deactivate(state) if done == TransitionCallbackReturn.SUCCESS else done

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._transition("cleanup", self.cleanup, UNCONFIGURED)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        return self._transition("shutdown", lambda: self._release(state.label), FINALIZED)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The error path: everything released, back to unconfigured (finalized if even that fails)."""
        self.get_logger().error(f"error from {state.label}: releasing everything ({self.lifecycle_problem})")
        try:
            self.cleanup()
        except Exception:
            self.get_logger().fatal(f"cleanup on the error path failed:\n{traceback.format_exc()}")
            self.lifecycle_state = FINALIZED
            return TransitionCallbackReturn.FAILURE
        self.lifecycle_state = UNCONFIGURED
        return TransitionCallbackReturn.SUCCESS

    def _refusing_unknown_transitions(self, change_state: Callable) -> Callable:
        """rclpy's change_state service raises for a transition id the present state does not
        have (finalized → configure), which ends the node's spin: it answers success=False."""

        def answer(request: ChangeState.Request, response: ChangeState.Response) -> ChangeState.Response:
            try:
                return change_state(request, response)
            except RuntimeError as error:  # rclpy's RCLError
                self.get_logger().warning(
                    f"transition {request.transition.id} refused in {self.lifecycle_state}: {error}"
                )
                response.success = False
                return response

        return answer

    def _transition(self, name: str, hook: Callable[[], None], reached: str, refusals=()) -> TransitionCallbackReturn:
        try:
            hook()
        except refusals as refused:
            self.lifecycle_problem = f"{name} refused: {refused}"
            self.get_logger().error(self.lifecycle_problem)
            return TransitionCallbackReturn.FAILURE
        except Exception as error:
            self.lifecycle_problem = f"{name} failed: {type(error).__name__}: {error}"
            self.get_logger().error(f"{name} failed:\n{traceback.format_exc()}")
            return TransitionCallbackReturn.ERROR
        self.lifecycle_state, self.lifecycle_problem = reached, ""
        self.get_logger().info(f"{name}: now {reached}")
        return TransitionCallbackReturn.SUCCESS

    def _release(self, state: str) -> None:
        """Leave ``state`` for good: deactivate if active, clean up if configured."""
        if state == ACTIVE:
            self.deactivate()
        if state in (ACTIVE, INACTIVE):
            self.cleanup()

    def destroy_node(self) -> None:
        """On SIGINT, SIGTERM or any other exit: what an active node holds is released first."""
        try:
            self._release(self.lifecycle_state)
        finally:
            self.lifecycle_state = FINALIZED
            super().destroy_node()

    # --- health ------------------------------------------------------------------------------
    def health(self) -> Health:
        return Health(
            DiagnosticStatus.OK,
            "up",
            {"mows_version": mows.__version__, **parameter_values(self, self.parameter_table)},
        )

    def _report(self) -> Health:
        """``health()`` with the lifecycle state; an error while a transition failed."""
        health = self.health()
        values = {"lifecycle_state": self.lifecycle_state, **health.values}
        if self.lifecycle_problem:
            return Health(DiagnosticStatus.ERROR, f"{self.lifecycle_state}: {self.lifecycle_problem}", values)
        message = health.message if self.active else f"{self.lifecycle_state}: {health.message}"
        return Health(health.level, message, values)
