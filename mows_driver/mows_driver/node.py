"""The driver node: ROS side of the device (the simulator, a serial device, a recorded bag).

It translates only: the device, the stream and the cycle are
:class:`mows.device.stream.session.DeviceSession`; the parameters are in ``parameters.py``, the
topics and the bag in ``outputs.py`` (published in order by a streaming thread,
``mows_ros.streaming``), the services in ``services.py`` (served on the executor while a cycle
or a supply ramp is awaited) and /diagnostics in ``health.py``.

A managed node (``mows_ros.node``): ``configure`` checks the parameters and opens the device
link (and the bag) and reads the device from then on; ``activate`` publishes the stream and
arms the session, the only state in which a coil may be energised; ``deactivate`` switches the
coils off at the device's next sample, fails a running cycle, ramps the supply to zero, stops
publishing the stream (``mows/excitation`` still says what the coils do) and refuses cycles
with the reason; ``cleanup`` closes the link. The rule is the core's
(:class:`mows.device.stream.session.DeviceSession` refuses to energise unless armed).

The node never dies on data and never publishes a number it did not measure: what goes
wrong is in the service responses, on /diagnostics and in the log. The coils are off in
every phase but EXCITING, in every lifecycle state but active, and when the node stops (SIGINT,
SIGTERM), and the static-field supply is ramped to zero when it stops.
"""

import functools

from rcl_interfaces.msg import SetParametersResult

from mows.device.backends.factory import BackendSettings, make_backend
from mows.device.stream.session import DeviceSession, continued
from mows.physics.coils import CurrentCap
from mows.precompile import precompile
from mows_driver.health import StreamHealth
from mows_driver.outputs import DriverOutputs
from mows_driver.parameters import (
    PARAMETERS,
    backend_settings,
    current_problem,
    cycle_settings,
    session_config,
    settings_problem,
    tracking_changed,
    tracking_settings,
)
from mows_driver.services import DriverServices
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import parameter_values
from mows_ros.process import run_node
from mows_ros.streaming import StreamThread

NODE_NAME = "driver"
POLL_S = 0.02  # the streaming thread's longest wait for the device
INACTIVE = "the driver is not active (lifecycle): coils off, no cycles, no supply current"


class DriverNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self.values = parameter_values(self, PARAMETERS)
        self.session: DeviceSession | None = None  # from configure to cleanup: the device link
        self._previous: DeviceSession | None = None  # the session a reconfigured driver goes on from
        self.outputs = DriverOutputs(self)
        self._health = StreamHealth()
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        self._service_calls = DriverServices(self)  # (Node has .services and ._services)
        self._streaming = StreamThread(self, "mows-driver-stream", self._step, POLL_S, ready=self._stream_ready)

    # --- the lifecycle ---------------------------------------------------------------------
    def configure(self) -> None:
        """Check the parameters together, open the device link and the bag, and stream from the
        device (published only while active), disarmed."""
        values = self.values
        if (problem := current_problem(values)) is not None:
            raise ValueError(problem)
        cap = CurrentCap(values["coil_current_cap_a"])
        settings = self.device_settings  # a ValueError or OSError refuses, with its reason
        # The cycle fits its tuning ring-downs and a simulated device integrates: compile both (or
        # load them from numba's cache) now, not while the device streams.
        self.get_logger().info(f"numba kernels ready in {precompile(simulator=settings.simulated):.1f} s")
        backend = make_backend(settings, cap)  # a ValueError or OSError refuses, with its reason
        try:
            self.outputs.record(values["record_path"])
        except BaseException:
            backend.close()
            raise
        self.session = DeviceSession(backend, continued(self._previous, session_config(values, cap, settings)))
        self.session.disarm(INACTIVE)
        if values["backend"] == "sim":  # the simulated stage starts where the parameter puts it
            self.session.stage_angle_rad = values["theta0_rad"]
        self.session.set_tracking(tracking_settings(values, settings))  # a ValueError refuses, with its reason
        self._streaming.start()

    def activate(self) -> None:
        assert self.session is not None  # activate comes after configure
        self.session.arm()

    def deactivate(self) -> None:
        """Coils off at the device's next sample, a running cycle failed, the supply ramped to
        zero; the stream is no longer published."""
        assert self.session is not None  # deactivate comes after activate
        self.session.disarm(INACTIVE)

    def cleanup(self) -> None:
        """Stop streaming, coils off, supply to zero, device released, bag closed."""
        self._streaming.stop()
        if self.session is not None:
            self.get_logger().info(f"device closed: {self.session.close() or 'nothing read back'}")
            self._previous, self.session = self.session, None
        self.outputs.close()

    # --- parameters ------------------------------------------------------------------------
    @functools.cached_property
    def device_settings(self) -> BackendSettings:
        """Made once: their parameters are fixed at start-up (ValueError, OSError while unreadable)."""
        return backend_settings(self.values)

    def _validate(self, parameters) -> SetParametersResult:
        """Checks across parameters (each one alone is checked by its table row)."""
        try:
            reason = settings_problem({**self.values, **{p.name: p.value for p in parameters}}, self.device_settings)
        except (OSError, ValueError) as unreadable:  # the scenario
            reason = str(unreadable)
        return SetParametersResult(successful=reason is None, reason=reason or "")

    def _apply(self, parameters) -> None:
        self.values = {**self.values, **{p.name: p.value for p in parameters}}
        if self.session is None:
            return  # configure reads them
        cycle = cycle_settings(self.values)
        retrack = tracking_changed(p.name for p in parameters)  # an emergency stop's end of tracking holds till then
        tracking = tracking_settings(self.values, self.device_settings) if retrack else None
        self.session.set_block_duration(self.values["block_duration_s"])
        self.session.set_cycle_settings(cycle)
        if retrack:
            self.session.set_tracking(tracking)

    def linked(self) -> DeviceSession:
        """The device session; ValueError, with the reason, while there is none."""
        if self.session is None:
            raise ValueError(f"the driver is {self.lifecycle_state}: no device link")
        return self.session

    # --- streaming -------------------------------------------------------------------------
    def _stream_ready(self) -> bool:
        """A live device is read from configure on (it streams whatever we do); a recording
        replays once, so it waits for an active driver with its subscribers."""
        if self.linked().backend.name != "bag":
            return True
        return self.active and self.outputs.raw.get_subscription_count() >= self.values["bag_wait_subscribers"]

    def _step(self) -> None:
        session = self.linked()
        self.outputs.publish(session.step(POLL_S), session, self.values)

    # --- health ----------------------------------------------------------------------------
    def health(self) -> Health:
        if self.session is None:
            return super().health()
        return self._health.report(self.session, super().health().values, self._streaming.errors, self.outputs.counts())


def main(args: list[str] | None = None) -> int:
    return run_node(DriverNode, args)
