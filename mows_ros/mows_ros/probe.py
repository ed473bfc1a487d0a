"""The ``probe_file`` parameter of the estimator and the mapper: a probe constants YAML
(:meth:`mows.physics.probe.Probe.from_yaml`), or empty for the paper's probe.

The file is read when the parameter is set, so that a missing or malformed file is refused
with its reason by ``ros2 param set`` (or stops the node at start-up) instead of failing in
the middle of a fit; setting the same path again reads it again.
"""

import yaml

from mows.physics.probe import PAPER_PROBE, Probe
from mows_ros.params import ParamSpec

_READ = {"": PAPER_PROBE}  # by path, as last read when the parameter was set


def probe_file_problem(path: str) -> str | None:
    try:
        _READ[path] = Probe.from_yaml(path) if path else PAPER_PROBE
    except (OSError, ValueError, TypeError, yaml.YAMLError) as error:
        return f"probe_file={path!r}: {error}"
    return None


def probe_of(path: str) -> Probe:
    """The probe of a ``probe_file`` value the node accepted."""
    return _READ[path]


PROBE_FILE = ParamSpec(
    "probe_file",
    "",
    "probe constants YAML (mows.physics.probe.Probe.from_yaml); empty: the paper's probe",
    check=probe_file_problem,
)
