"""A cycle started by another thread (the driver's executor) while the streaming thread is
between its poll of the device and taking what the poll read: those samples came from the
device before the cycle's first command reached it, so they hold no answer to it and must not
run out the answer's deadline (``confirm_timeout_s`` of device samples). On a loaded host the
streaming thread reads more than that at once after a stall: the cycle failed with "the device
did not answer OrientationCommand … in 0.5 s" although the device had answered at once."""

import threading

from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_ringdown
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

CAP_A = 10.0
QUICK = CycleSettings(excite_s=0.3, ringdown_s=0.3, gap_s=0.1, repeats=1, tuning_steps=0, turn_settle_s=0.1)
STALL_S = 2 * QUICK.confirm_timeout_s  # what one poll reads after the streaming thread stalled
# How long the poll holds its samples for the other thread's start to send its command: a start
# that waits for the take (as it must) sends none, so the poll goes on after this; one that does
# not wait has sent long before. Not a pass criterion: a correct session passes at any load.
HOLD_S = 1.0
MAX_STEPS = 10_000  # bound for a loop that never ends (a bug), not a timing


class StartedMeanwhile(SimBackend):
    """A simulated device whose next poll, once it has read, starts ``meanwhile`` on a thread of
    its own and holds what it read until that has sent a command (or ``HOLD_S``): as the
    driver's executor starting a cycle in that gap does."""

    meanwhile = None
    thread: threading.Thread | None = None
    sent = threading.Event()

    def poll(self, timeout_s: float) -> list:
        items = super().poll(timeout_s)
        if self.meanwhile is not None:
            self.thread = threading.Thread(target=self.meanwhile)
            self.meanwhile = None
            self.thread.start()
            self.sent.wait(HOLD_S)
        return items

    def send(self, command) -> None:
        super().send(command)
        self.sent.set()


def test_a_cycle_started_between_a_poll_and_its_take_is_answered_and_runs_to_the_end():
    scenario = load_scenario("calibration")
    device = SimulatedDevice(scenario)
    backend = StartedMeanwhile(device, CurrentCap(CAP_A), paced=False, chunk_s=STALL_S)
    session = DeviceSession(
        backend, SessionConfig(0.025, QUICK, scenario.setup, CurrentCap(CAP_A), 125.0, fit_ringdown)
    )
    session.arm()
    session.step(0.0)
    outcomes = []
    backend.meanwhile = lambda: session.start_cycle(CycleRequest(1.0), outcomes.append)
    for _ in range(MAX_STEPS):
        if outcomes:
            break
        session.step(0.0)
    assert backend.thread is not None
    backend.thread.join()
    (outcome,) = outcomes
    assert outcome.success and outcome.ringdowns_recorded == 1, outcome.message
