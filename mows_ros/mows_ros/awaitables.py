"""What a coroutine callback awaits on a node spun by one thread (``mows_ros.process``): a
future with a time limit, a condition polled until a deadline, a service's answer, a value
another callback delivers (or a fallback at a time limit), a CPU-bound function run in a
worker thread, and a result another thread delivers. Each resumes the coroutine at the
executor's next turn; none blocks the thread that serves the node's other callbacks. Time
limits are real time (``mows_ros.wall``), also under ``use_sim_time``.
"""

import threading
import time
from collections.abc import Callable

from rclpy.client import Client
from rclpy.node import Node
from rclpy.task import Future

from mows_ros.wall import steady_timer

POLL_S = 0.05  # how often ``until`` looks at its condition


def _settle(future: Future, value) -> None:
    if not future.done():
        future.set_result(value)


async def within(node: Node, future: Future, timeout_s: float) -> bool:
    """Await ``future`` for at most ``timeout_s``: True if it completed, else False (and it is
    cancelled)."""
    either = Future()
    future.add_done_callback(lambda _: _settle(either, True))
    timer = steady_timer(node, timeout_s, lambda: _settle(either, False))
    try:
        completed = await either
    finally:
        node.destroy_timer(timer)
    if not completed:
        future.cancel()
    return completed


async def until(node: Node, condition: Callable[[], bool], timeout_s: float) -> bool:
    """Await ``condition()`` becoming true, looked at every POLL_S for at most ``timeout_s``."""
    if condition():
        return True
    deadline = time.monotonic() + timeout_s
    answer = Future()

    def look() -> None:
        if condition():
            _settle(answer, True)
        elif time.monotonic() > deadline:
            _settle(answer, False)

    timer = steady_timer(node, POLL_S, look)
    try:
        return await answer
    finally:
        node.destroy_timer(timer)


async def call(node: Node, client: Client, request, timeout_s: float):
    """``client``'s response to ``request``, or None: the service did not appear (it may not be
    discovered yet) or did not answer, each within ``timeout_s``."""
    if not await until(node, client.service_is_ready, timeout_s):
        return None
    future = client.call_async(request)
    return future.result() if await within(node, future, timeout_s) else None


class Delivery:
    """A value one callback delivers (:meth:`deliver`) to the coroutine that awaits it
    (:meth:`wait`), or what ``fallback()`` gives once the wait's time is up."""

    def __init__(self, node: Node):
        self._node = node
        self._due = Future()
        self._due.set_result(None)  # nobody waits yet: deliveries are dropped

    def deliver(self, value) -> None:
        """Resume the waiting coroutine with ``value`` (None, or nobody waiting: nothing)."""
        if value is not None:
            _settle(self._due, value)

    async def wait(self, timeout_s: float, fallback: Callable[[], object]):
        """The next value delivered, or ``fallback()``'s (when not None) after ``timeout_s``."""
        self._due = Future()
        timer = steady_timer(self._node, timeout_s, lambda: self.deliver(fallback()))
        try:
            return await self._due
        finally:
            self._node.destroy_timer(timer)


def completer(node: Node, future: Future) -> Callable[[object], None]:
    """A function another thread calls with ``future``'s result (an exception: to raise)."""
    executor = node.executor

    def complete(value) -> None:
        if isinstance(value, Exception):
            future.set_exception(value)
        else:
            future.set_result(value)
        if node.context.ok():  # at shutdown nobody is waiting
            executor.wake()  # the awaiting coroutine resumes at the executor's next turn

    return complete


async def in_worker(node: Node, function: Callable, *args, **kwargs):
    """``function(*args, **kwargs)`` in a thread of its own, its result (or exception) awaited."""
    finished = Future()
    complete = completer(node, finished)

    def work() -> None:
        try:
            complete(function(*args, **kwargs))
        except Exception as error:  # raised again where the result is awaited
            complete(error)

    threading.Thread(target=work, name=f"{node.get_name()}-worker", daemon=True).start()
    return await finished
