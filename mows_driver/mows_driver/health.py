"""What the driver says on /diagnostics: the device session's state, and what went wrong
since the last report (new gaps, new device faults) or still is wrong."""

from diagnostic_msgs.msg import DiagnosticStatus

from mows.device.stream.session import DeviceSession
from mows_ros.diagnostics import Health

RATE_TOLERANCE = 0.02  # warn when the achieved sample rate is further off nominal


class StreamHealth:
    """The level and message of the driver's status, from the session's ``health()`` state."""

    def __init__(self):
        self._reported_gaps = 0
        self._reported_faults = 0

    def report(self, session: DeviceSession, node_values: dict, stream_errors: int, counts: dict) -> Health:
        """The driver's status: ``node_values`` (the node's own), the session's state and rates,
        ``stream_errors`` and ``counts`` (published, recorded)."""
        state = session.health()
        info = session.backend.info
        values = {
            **node_values,
            **state,
            "nominal_sample_rate_hz": info.sample_rate_hz if info else None,
            "achieved_sample_rate_hz": session.achieved_rate_hz(),
            "blocks_published": counts["blocks_published"],
            "stream_errors": stream_errors,
            "recorded_messages": counts["recorded_messages"],
        }
        return self(state, session.backend.name, stream_errors, values)

    def __call__(self, state: dict, backend: str, stream_errors: int, values: dict) -> Health:
        nominal, achieved = values["nominal_sample_rate_hz"], values["achieved_sample_rate_hz"]
        new_gaps, self._reported_gaps = state.get("gaps", 0) - self._reported_gaps, state.get("gaps", 0)
        new_faults, self._reported_faults = state["device_faults"] - self._reported_faults, state["device_faults"]
        if state["link"] == "finished":
            return Health(DiagnosticStatus.OK, "replay finished", values)
        if not state["link_up"]:
            return Health(
                DiagnosticStatus.ERROR, f"no device: {state['link_reason'] or state.get('last_error')}", values
            )
        problems = []
        if state.get("estop_latched"):
            problems.append(f"emergency stop latched ({state['estop_reason']})")
        if state.get("fault"):  # until the next cycle starts (an emergency stop: until released)
            problems.append(f"the last cycle failed: {state['fault']}")
        if new_faults:
            problems.append(f"device fault: {state['last_device_fault']}")
        if new_gaps:
            restarts = f", {state['device_restarts']} device restarts" if state.get("device_restarts") else ""
            problems.append(
                f"{new_gaps} new gaps in the sample stream ({state['missing_samples']} samples "
                f"missing in all{restarts})"
            )
        if achieved is not None and nominal and abs(achieved / nominal - 1.0) > RATE_TOLERANCE:
            problems.append(f"sample rate {achieved:.0f} Hz, nominal {nominal:.0f} Hz")
        if stream_errors:
            problems.append(f"{stream_errors} streaming errors (see the log)")
        if problems:
            return Health(DiagnosticStatus.WARN, "; ".join(problems), values)
        count = state.get("probes", 0)
        probes = f", ringing {count} probe{'' if count == 1 else 's'}" if count else ""
        # Disarmed (not active), the device is read but nothing is published.
        doing = "streaming" if state.get("armed") else "reading the device, publishing nothing"
        return Health(DiagnosticStatus.OK, f"{doing} ({backend}{probes}), phase {state.get('phase')}", values)
