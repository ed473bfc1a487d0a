"""Action servers whose refusals reach the client.

A goal rejected in rclpy's goal callback reaches an action client as "Goal was rejected." and
nothing more. So every MOWS action server accepts each goal, and its execute callback aborts a
goal it cannot run at once, before anything moves, with the reason in the result's message.
"""

from collections.abc import Callable, Sequence

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node

from mows.sweep.requests import Ending, goal_ending


def action_servers(
    node: Node,
    action_type,
    names: Sequence[str],
    execute: Callable,
    cancel: Callable[[object], CancelResponse],
    group: CallbackGroup,
) -> list[ActionServer]:
    """One server of ``action_type`` under each of ``names`` (a node's own name, then the
    previous release's alias), all with the same callbacks; every goal is accepted."""
    return [
        ActionServer(
            node,
            action_type,
            name,
            execute,
            goal_callback=lambda _: GoalResponse.ACCEPT,
            cancel_callback=cancel,
            callback_group=group,
        )
        for name in names
    ]


def end_goal(goal_handle, succeeded: bool, cancelled: bool) -> None:
    """End ``goal_handle`` as :func:`mows.sweep.requests.goal_ending` says: cancelled (whatever
    else) as its client asked, succeeded or aborted; a goal the node cancelled itself, its client
    gone (``mows_ros.requesters``), ends aborted."""
    ending = goal_ending(succeeded, cancelled, goal_handle.is_cancel_requested)
    if ending == Ending.CANCELED:
        goal_handle.canceled()
    elif ending == Ending.SUCCEEDED:
        goal_handle.succeed()
    else:
        goal_handle.abort()
