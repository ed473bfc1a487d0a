"""The README lists every topic, service, action and parameter of the four nodes."""
from pathlib import Path

import pytest

from mows_calibrator import node as calibrator
from mows_driver import node as driver
from mows_estimator import node as estimator
from mows_mapper import node as mapper

pytestmark = pytest.mark.ros

README = (Path(__file__).parents[2] / "README.md").read_text()
INTERFACES = ["/mows/raw", "/mows/excitation", "/mows/ringdown", "/mows/field", "/mows/magnetic_field",
              "/mows/sweep", "/mows/model_report", "/diagnostics", "/mows/driver/run_cycle",
              "/mows/driver/emergency_stop", "/mows/driver/set_field_current", "/mows/estimator/calibrate",
              "/mows/mapper/rotation_sweep", "/mows/calibrator/calibrate_probe"]


@pytest.mark.parametrize("module", [driver, estimator, mapper, calibrator],
                         ids=["driver", "estimator", "mapper", "calibrator"])
def test_every_parameter_is_in_the_readme(module):
    assert [spec.name for spec in module.PARAMETERS if f"`{spec.name}`" not in README] == []


def test_every_topic_service_and_action_is_in_the_readme():
    assert [name for name in INTERFACES if f"`{name}`" not in README] == []
