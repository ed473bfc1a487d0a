"""The probe mount's URDF for several probes: the shipped mount of one probe
(``urdf/mows_probe_mount.urdf``) with, for each probe of a ``probes`` list
(:mod:`mows.estimate.probe_set`), its rotation plane and its probe frame.

Probe k's rotation plane ``mows_rotation_plane_<k>`` sits at its ``position_m`` in
``mows_rotation_plane`` (the same axes), and ``mows_probe_<k>`` turns in it on the joint
``mows_stage_<k>``, which mimics ``mows_stage``: every probe is turned about its own magnet to
the θ0 the driver publishes on /mows/joint_states, so robot_state_publisher gives every probe's
frame from that one joint. The frame names are those the estimator's fits and the mapper's
sweeps carry with ``probes``.

    python -m mows_bringup.mount "{0: 112.48, 1: {f00_hz: 125.0, position_m: [0, 0.05, 0]}}" > mount.urdf
"""

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from ament_index_python.packages import get_package_share_directory

from mows.estimate.probe_set import ProbeEntry, probe_frame_id
from mows.estimate.settings import probe_set
from mows_driver.messages import STAGE_JOINT
from mows_estimator.parameters import PARAMETERS as ESTIMATOR
from mows_mapper.parameters import PARAMETERS as MAPPER
from mows_ros.probe import probe_of

# The frames the nodes name with their defaults: the mapper's plane, the estimator's probe.
PLANE = next(spec.default for spec in MAPPER if spec.name == "frame_id")
PROBE = next(spec.default for spec in ESTIMATOR if spec.name == "probe_frame_id")


def shipped_mount() -> Path:
    return Path(get_package_share_directory("mows_bringup")) / "urdf" / "mows_probe_mount.urdf"


def probes_mount(probes: tuple[ProbeEntry, ...], mount: Path | None = None) -> str:
    """The URDF text of the mount with every probe's frames (module docstring)."""
    robot = ET.parse(mount or shipped_mount()).getroot()
    for entry in probes:
        plane, probe, joint = (probe_frame_id(base, entry.probe_id, named=True) for base in (PLANE, PROBE, STAGE_JOINT))
        ET.SubElement(robot, "link", name=plane)
        ET.SubElement(robot, "link", name=probe)
        fixed = ET.SubElement(robot, "joint", name=f"{plane}_mount", type="fixed")
        ET.SubElement(fixed, "parent", link=PLANE)
        ET.SubElement(fixed, "child", link=plane)
        ET.SubElement(fixed, "origin", xyz=" ".join(repr(x) for x in entry.position_m), rpy="0 0 0")
        stage = ET.SubElement(robot, "joint", name=joint, type="continuous")
        ET.SubElement(stage, "parent", link=plane)
        ET.SubElement(stage, "child", link=probe)
        ET.SubElement(stage, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(stage, "axis", xyz="0 0 1")
        ET.SubElement(stage, "mimic", joint=STAGE_JOINT)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def main(args: list[str] | None = None) -> int:
    """Print the mount of the ``probes`` value given (probe files read as the nodes read them)."""
    args = sys.argv[1:] if args is None else args
    if len(args) != 1:
        print("usage: python -m mows_bringup.mount PROBES  (the estimator's probes value)", file=sys.stderr)
        return 2
    try:
        probes = probe_set(args[0], probe_of(""))
    except (OSError, ValueError) as error:
        print(f"probes={args[0]!r}: {error}", file=sys.stderr)
        return 2
    sys.stdout.write(probes_mount(probes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
