"""A busy robot computer beside the graph, for ``mows-latency --load``: CPU burners (processes
that only spin) and a robot's control loop stand-in, a ``sensor_msgs/JointState`` publisher at
1 kHz on ``/joint_states`` in the same ROS domain, with a subscriber in another process (as
robot_state_publisher would be) so the messages really cross DDS.

Each runs in a process of its own (spawned, not forked: rclpy's context must not be shared).
:class:`Load` reports what it achieved: the rate published and the rate received, never the
rate asked for.
"""

import multiprocessing
import os
import queue
import time

import rclpy
from sensor_msgs.msg import JointState

JOINT_TOPIC = "joint_states"
JOINT_NAMES = tuple(f"joint_{i}" for i in range(1, 7))  # a six-axis arm
JOINT_DEPTH = 10  # reliable, volatile: robot_state_publisher's and ros2_control's default


def burn(stop, nice: int) -> None:
    """Spin until told to stop: one core's worth of load (less when the cores are shared), at
    niceness ``nice`` (0: the graph's own priority, as a robot stack's busy processes)."""
    os.nice(nice)
    while not stop.is_set():
        for _ in range(100_000):
            pass


def publish_joint_states(rate_hz: float, stop, report) -> None:
    """A control loop's JointState at ``rate_hz`` on absolute deadlines; a tick missed (the
    process did not run in time) is skipped, not made up in a burst, as a control loop does."""
    rclpy.init()
    node = rclpy.create_node("mows_load_control_loop")
    publisher = node.create_publisher(JointState, JOINT_TOPIC, JOINT_DEPTH)
    message = JointState(name=list(JOINT_NAMES), position=[0.0] * 6, velocity=[0.0] * 6, effort=[0.0] * 6)
    period_ns = round(1e9 / rate_hz)
    start_ns = next_ns = time.monotonic_ns()
    published = 0
    while not stop.is_set():
        now_ns = time.monotonic_ns()
        if now_ns < next_ns:
            time.sleep((next_ns - now_ns) * 1e-9)
            continue
        message.header.stamp = node.get_clock().now().to_msg()
        message.position[0] = (now_ns - start_ns) * 1e-9  # a joint that moves
        publisher.publish(message)
        published += 1
        next_ns += period_ns * ((now_ns - next_ns) // period_ns + 1)
    report.put(("published_hz", published / ((time.monotonic_ns() - start_ns) * 1e-9)))
    node.destroy_node()
    rclpy.try_shutdown()


def listen_joint_states(stop, report) -> None:
    """Counts the JointState messages that arrive, from the first one on."""
    rclpy.init()
    node = rclpy.create_node("mows_load_listener")
    arrivals = []
    node.create_subscription(JointState, JOINT_TOPIC, lambda _m: arrivals.append(time.monotonic()), JOINT_DEPTH)
    while not stop.is_set():
        rclpy.spin_once(node, timeout_sec=0.05)
    span_s = arrivals[-1] - arrivals[0] if len(arrivals) > 1 else 0.0
    report.put(("received_hz", (len(arrivals) - 1) / span_s if span_s > 0 else 0.0))
    node.destroy_node()
    rclpy.try_shutdown()


class Load:
    """``burners`` spinning processes and a JointState loop at ``joint_rate_hz``, from
    :meth:`start` to :meth:`stop`, which returns what was achieved."""

    def __init__(self, burners: int = 2, joint_rate_hz: float = 1000.0, burner_nice: int = 0):
        context = multiprocessing.get_context("spawn")
        self._stop = context.Event()
        self._report = context.Queue()
        self.burners, self.joint_rate_hz, self.burner_nice = burners, joint_rate_hz, burner_nice
        self._processes = [
            context.Process(target=burn, args=(self._stop, burner_nice), daemon=True) for _ in range(burners)
        ]
        self._processes += [
            context.Process(target=listen_joint_states, args=(self._stop, self._report), daemon=True),
            context.Process(target=publish_joint_states, args=(joint_rate_hz, self._stop, self._report), daemon=True),
        ]
        self._load_average_start = os.getloadavg()

    def start(self) -> None:
        self._load_average_start = os.getloadavg()
        for process in self._processes:
            process.start()

    def stop(self) -> dict:
        """Stops every process and returns the load as run: burners, JointState rates asked,
        published and received, the machine's 1-minute load average at the start and the end."""
        load_average_end = os.getloadavg()
        self._stop.set()
        achieved = {}
        for _ in range(2):
            try:
                key, value = self._report.get(timeout=10.0)
            except queue.Empty:  # a process that died says nothing: its figure stays NaN
                break
            achieved[f"joint_state_{key}"] = value
        for process in self._processes:
            process.join(timeout=10.0)
            if process.is_alive():
                process.kill()
        return {
            "cpu_burners": self.burners,
            "burner_nice": self.burner_nice,
            "joint_state_asked_hz": self.joint_rate_hz,
            "joint_state_published_hz": achieved.get("joint_state_published_hz", float("nan")),
            "joint_state_received_hz": achieved.get("joint_state_received_hz", float("nan")),
            "load_average_1min_start": self._load_average_start[0],
            "load_average_1min_end": load_average_end[0],
            "cpu_cores": os.cpu_count(),
        }
