"""Runs one rotation sweep through the graph it finds and prints the outcome as JSON (one line):
for tests that must put the client in another network namespace than pytest's own. With the
outcome: the measurement ring-downs the driver announced, the fits it heard, by status, and the
last diagnostics of the driver and the estimator. It waits, after the sweep, until a fit of every
announced ring-down is heard and the estimator's counts take them all in: a fit over a gap may
come after the sweep's answer (the mapper goes on without a cycle's fits after its
fit_timeout_s), and one that never comes is a failure (the client gives up at BOUND_S).

    python sweep_client.py THETA0_DEG,... REPEATS BOUND_S
"""

import collections
import json
import math
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.action import RotationSweep
from mows_msgs.msg import ExcitationState, MagnetometerBlock, RingdownFit
from rclpy.action import ActionClient

from mows_ros.qos import RESULT_QOS, STREAM_QOS


def main(angles_deg: str, repeats: str, bound_s: str) -> int:
    rclpy.init()
    node = rclpy.create_node("sweep_client")
    blocks, statuses, fits, announced = [], {}, [], set()
    node.create_subscription(MagnetometerBlock, "/mows/raw", blocks.append, STREAM_QOS)
    node.create_subscription(RingdownFit, "/mows/ringdown", fits.append, RESULT_QOS)
    node.create_subscription(
        ExcitationState,
        "/mows/excitation",
        lambda s: (
            announced.add((s.cycle_id, s.repeat_index))
            if s.phase == ExcitationState.PHASE_RINGDOWN and not s.tuning
            else None
        ),
        RESULT_QOS,
    )
    node.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda a: statuses.update(
            (s.name, {"level": ord(s.level), **{kv.key: kv.value for kv in s.values}}) for s in a.status
        ),
        10,
    )
    client = ActionClient(node, RotationSweep, "/mapper/rotation_sweep")
    deadline = time.monotonic() + float(bound_s)

    def spin_until(condition, what):
        while not condition():
            if time.monotonic() > deadline:
                raise TimeoutError(f"gave up waiting for {what() if callable(what) else what}")
            rclpy.spin_once(node, timeout_sec=0.1)
        return condition()

    spin_until(lambda: client.server_is_ready() and blocks, "the sweep action and the driver's stream")
    # The estimator hears the stream (discovery takes seconds on a loaded machine): a ring-down
    # over before its first block would be counted by it, not fitted.
    spin_until(lambda: int(statuses.get("/estimator", {}).get("blocks", 0)), "the estimator hearing the stream")
    goal = RotationSweep.Goal(
        theta0_rad=[math.radians(float(a)) for a in angles_deg.split(",")], repeats_per_angle=int(repeats)
    )
    sent = client.send_goal_async(goal)
    handle = spin_until(lambda: sent.done() and sent.result(), "the goal's answer")
    result = handle.get_result_async()
    done = spin_until(lambda: result.done() and result.result(), "the sweep")
    spin_until(
        lambda: "/driver" in statuses and len(fits) == len(announced) == _fits_counted(statuses.get("/estimator")),
        lambda: (
            f"a fit of each of the {len(announced)} ring-downs announced (heard {len(fits)}, the estimator "
            f"counts {_fits_counted(statuses.get('/estimator'))})"
        ),
    )
    print(
        json.dumps(
            {
                "accepted": handle.accepted,
                "success": done.result.success,
                "message": done.result.message,
                "n_points": done.result.decomposition.n_points,
                "blocks_heard": len(blocks),
                "ringdowns_announced": len(announced),
                "fits": collections.Counter(f.status_name for f in fits),
                "failed_fits_with_numbers": sum(
                    f.status != RingdownFit.STATUS_OK and math.isfinite(f.frequency_hz) for f in fits
                ),
                "estimator": statuses["/estimator"],
                "driver": statuses["/driver"],
            }
        )
    )
    node.destroy_node()
    rclpy.shutdown()
    return 0


def _fits_counted(status) -> int | None:
    """How many fits the estimator says it published (measurement ring-downs: tuning ones are not fitted)."""
    return None if status is None else int(status["fits_ok"]) + int(status["fits_failed"])


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
