"""What the mapper publishes at a sweep's end (mows.sweep.publication), without ROS.

Requirement: one probe's sweep publishes its decomposition only when the runner hands it over
(a failed one has no numbers to show), and the model lab reads it only with a reference;
several probes' sweeps publish every probe's decomposition, each in its own frame, and the
field map of them all, and the lab (which reads one probe's sweep) is not run even with a
reference. A cycle the driver failed is said as "cycle failed: why"; one that ran is as it came.
"""

import pytest

from mows.estimate.probe_set import ProbeEntry
from mows.physics.probe import PAPER_PROBE
from mows.sweep.decomposition import Decomposition, DecompositionStatus
from mows.sweep.events import CycleAnswer, SweepMap, SweepSettings, SweepStep
from mows.sweep.publication import Publication, cycle_failed, publication
from mows.sweep.record import SweepRecord

PROBES = (ProbeEntry(0, PAPER_PROBE, 112.5), ProbeEntry(1, PAPER_PROBE, 125.0))
OWN = SweepSettings(probes=PROBES[:1])  # the mapper's own probe: a set of one, not named
NAMED = SweepSettings(probes=PROBES, named=True)


def sweep_map(probe_id=0):
    failed = Decomposition("first_principles", DecompositionStatus.NO_DECOMPOSITION, "no ring-down")
    return SweepMap(3, failed, SweepRecord(), 112.5, probe_id)


@pytest.mark.parametrize("reference", ["", "anti_helmholtz"])
def test_one_probes_sweep_is_published_when_handed_over_and_read_by_the_lab_with_a_reference(reference):
    single = sweep_map()
    plan = publication(SweepStep(publish=(single,)), OWN, reference)
    assert plan == Publication((single,), lab=single if reference else None)
    assert plan.summary("report") == "sweep 3: report"
    assert publication(SweepStep(), OWN, reference) == Publication()


def test_several_probes_are_each_published_in_their_frames_with_the_field_map_and_no_lab():
    maps = (sweep_map(0), sweep_map(1))
    plan = publication(SweepStep(publish=maps), NAMED, "anti_helmholtz")
    assert plan.sweeps == maps and plan.per_probe and plan.field_map == PROBES and plan.lab is None
    assert plan.summary("report") == "sweep of 2 probes: report"


def test_one_named_probe_is_published_as_several_are_in_its_frame_with_the_field_map():
    single = sweep_map()
    plan = publication(SweepStep(publish=(single,)), SweepSettings(probes=PROBES[:1], named=True), "anti_helmholtz")
    assert plan == Publication((single,), per_probe=True, field_map=PROBES[:1])


def test_a_cycle_the_driver_failed_is_said_as_the_cycles_failure():
    assert cycle_failed(CycleAnswer(problem="coil current above the cap")).problem == (
        "cycle failed: coil current above the cap"
    )
    ran = CycleAnswer(7, 2)
    assert cycle_failed(ran) == ran
