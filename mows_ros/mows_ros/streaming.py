"""A node's streaming thread: it steps a source (a device link, a recording) from start to
stop, on a thread of its own rather than the executor, so that a service waiting on the
source never blocks the reading of it.

The thread never dies on a step that raises: the error is logged with its traceback and
counted (``errors``, for /diagnostics), and the next step follows a pause, unless the node's
context is shutting down, which ends the thread quietly. Before the first step it waits until
``ready()`` holds (a recording replays once: it waits for its subscribers).
"""

import threading
import time
import traceback
from collections.abc import Callable

from rclpy.node import Node


class StreamThread:
    """Calls ``step()`` on a daemon thread named ``name`` from :meth:`start` to :meth:`stop`;
    ``poll_s`` (s): the pause while not ready and after a failed step (``step`` itself should
    wait no longer than that for its source, so that :meth:`stop` is prompt)."""

    def __init__(self, node: Node, name: str, step: Callable[[], None], poll_s: float, ready=lambda: True):
        self._node, self._name, self._step, self._poll_s, self._ready = node, name, step, poll_s, ready
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self.errors = 0

    def start(self) -> None:
        self._stopping.clear()
        self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ends the thread after its current step (idempotent)."""
        self._stopping.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join()
        self._thread = None

    def _run(self) -> None:
        while not self._ready() and not self._stopping.wait(self._poll_s):
            pass
        while not self._stopping.is_set():
            try:
                self._step()
            except Exception:  # a bug must not stop the stream; it is logged and counted
                if not self._node.context.ok():
                    return
                self.errors += 1
                self._node.get_logger().error(f"streaming step failed:\n{traceback.format_exc()}")
                time.sleep(self._poll_s)
