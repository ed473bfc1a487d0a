"""The ``probe_file`` parameter of the estimator and the mapper: a probe constants YAML
(:meth:`mows.physics.probe.Probe.from_yaml`), or empty for the paper's probe; and their
``probes`` parameter, the probes sharing each ring-down window (:mod:`mows.estimate.probe_set`,
read by :func:`mows.estimate.settings.probe_set`).

The file is read when the parameter is set, so that a missing or malformed file is refused
with its reason by ``ros2 param set`` (or stops the node at start-up) instead of failing in
the middle of a fit; setting the same path again reads it again.
"""

from mows.estimate.settings import probe_set
from mows.physics.probe import PAPER_PROBE, Probe
from mows_ros.params import ParamSpec

_READ = {"": PAPER_PROBE}  # by path, as last read when the parameter was set


def probe_file_problem(path: str) -> str | None:
    try:
        _READ[path] = Probe.from_yaml(path) if path else PAPER_PROBE
    except ValueError as error:  # every refusal of a file or text, on one line
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


def probes_problem(text: str) -> str | None:
    """Why ``probes`` cannot be read, or None (its bare f00s checked with the paper's probe)."""
    try:
        probe_set(text, PAPER_PROBE)
    except ValueError as error:  # every refusal of a file or text, on one line
        return f"probes={text!r}: {error}"
    return None


PROBES = ParamSpec(
    "probes",
    "",
    "several probes in each ring-down window: YAML mapping of probe id to f00 (Hz), a probe file, "
    "or {f00_hz, f00_std_hz, probe_file, position_m} (mows.estimate.probe_set); empty: the node's own probe alone",
    check=probes_problem,
)
