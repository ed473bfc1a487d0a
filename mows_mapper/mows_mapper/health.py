"""What the mapper says on /diagnostics: the sweep runner's state and how its last sweep ended."""

from diagnostic_msgs.msg import DiagnosticStatus

from mows.sweep.runner import SweepRunner
from mows_ros.diagnostics import Health


def sweep_health(runner: SweepRunner) -> Health:
    """WARN with the reason while the last sweep failed; OK with how it ended when it was cancelled;
    otherwise OK with the last decomposition's report."""
    failure, cancel = runner.last_failure, runner.last_cancel
    values = {
        "state": runner.state,
        "sweeps": runner.sweeps,
        "last_failure": failure,
        "cancels": runner.cancels,
        "last_cancel": cancel,
    }
    if failure:
        return Health(DiagnosticStatus.WARN, f"the last sweep failed: {failure}", values)
    if cancel:
        return Health(DiagnosticStatus.OK, f"the last sweep was {cancel}", values)
    return Health(DiagnosticStatus.OK, runner.last, values)
