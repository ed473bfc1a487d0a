"""The viz node's parameter table and the View's settings from it."""

from mows.viz.view import ViewSettings
from mows_ros.params import ParamSpec

PARAMETERS = (
    ParamSpec(
        "port",
        8765,
        "the Foxglove WebSocket server's TCP port (0: any free port, logged)",
        range=(0, 65535),
        read_only=True,
    ),
    ParamSpec("host", "127.0.0.1", "the address the server listens on (0.0.0.0: every interface)", read_only=True),
    ParamSpec(
        "mount_file", "", "the probe mount's URDF, for its frames on /mows/viz/frames; empty: no frames", read_only=True
    ),
    ParamSpec(
        "channels",
        "difference",
        "what the estimator fits (its channels parameter): the ring-down plot combines the samples alike",
        choices=("difference", "channel1", "channel2"),
    ),
    ParamSpec(
        "raw_rate_hz", 1000.0, "the raw stream's plotted rate (samples averaged down to it), Hz", range=(1.0, 100000.0)
    ),
    ParamSpec(
        "buffer_s", 20.0, "raw samples kept to draw each ring-down under its fit, s", range=(0.5, 60.0), read_only=True
    ),
    ParamSpec(
        "coil_current_cap_a",
        10.0,
        "the driver's coil_current_cap_a, which the coil currents are shown against, A",
        range=(0.01, 100.0),
    ),
    ParamSpec(
        "arrow_length_m",
        0.05,
        "length of the largest field arrow and of the largest gradient arrow, m",
        range=(0.001, 10.0),
    ),
)


def view_settings(values: dict) -> ViewSettings:
    names = ("channels", "raw_rate_hz", "buffer_s", "coil_current_cap_a", "arrow_length_m")
    return ViewSettings(**{name: values[name] for name in names})
