"""docs/nodes.md lists every topic, service, action and parameter of the five nodes (the viz
node's Foxglove channels too), and
docs/command_line.md's environment for running them by hand finds every interface package."""

import os
import subprocess
from pathlib import Path

import pytest

from mows.viz import channels
from mows_calibrator import node as calibrator
from mows_driver import node as driver
from mows_estimator import node as estimator
from mows_mapper import node as mapper
from mows_viz import node as viz

pytestmark = pytest.mark.ros

ROOT = Path(__file__).parents[2]
NODES_DOC = (ROOT / "docs" / "nodes.md").read_text()
COMMAND_LINE_DOC = (ROOT / "docs" / "command_line.md").read_text()
INTERFACES = [
    "/mows/raw",
    "/mows/excitation",
    "/mows/supply",
    "/mows/joint_states",
    "/mows/ringdown",
    "/mows/field",
    "/mows/magnetic_field",
    "/mows/sweep",
    "/mows/field_map",
    "/mows/model_report",
    "/mows/workspace_model",
    "/diagnostics",
    # services and actions are node-private: their names in the root namespace
    "/driver/measurement_cycle",
    "/driver/run_cycle",
    "/driver/emergency_stop",
    "/driver/set_field_current",
    "/estimator/calibrate",
    "/mapper/rotation_sweep",
    "/mapper/confirm_orientation",
    "/mapper/workspace_map",
    "/mapper/field_at",
    "/calibrator/calibrate_probe",
    "/calibrator/confirm_orientation",
]
FOXGLOVE_CHANNELS = channels.TOPICS


@pytest.mark.parametrize(
    "module",
    [driver, estimator, mapper, calibrator, viz],
    ids=["driver", "estimator", "mapper", "calibrator", "viz"],
)
def test_every_parameter_is_in_the_nodes_doc(module):
    assert [spec.name for spec in module.PARAMETERS if f"`{spec.name}`" not in NODES_DOC] == []


def test_every_topic_service_and_action_is_in_the_nodes_doc():
    assert [name for name in INTERFACES if f"`{name}`" not in NODES_DOC] == []


def test_every_foxglove_channel_of_the_viz_node_is_in_the_nodes_doc():
    assert len(FOXGLOVE_CHANNELS) == 8
    assert [name for name in FOXGLOVE_CHANNELS if f"`{name}`" not in NODES_DOC] == []


def test_the_by_hand_environment_lets_the_ament_index_find_every_interface_package():
    """What `ros2 interface show mows_msgs/msg/RingdownFit` needs: mows_msgs and the packages
    it uses (std_msgs, from the wheels in the venv) in the ament index."""
    assert "`source env.bash`" in COMMAND_LINE_DOC
    clean = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "VIRTUAL_ENV", "PYTHONPATH")}
    script = (
        "from ament_index_python import get_resource\n"
        "for package in ('mows_msgs', 'std_msgs', 'sensor_msgs', 'diagnostic_msgs'):\n"
        "    print(package, get_resource('rosidl_interfaces', package)[1])"
    )
    run = subprocess.run(
        ["bash", "-c", f'source env.bash && python -c "{script}"'],
        cwd=ROOT,
        env=clean,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    assert len(run.stdout.splitlines()) == 4
