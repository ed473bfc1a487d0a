"""The mapper node with three probes: a rotation sweep through a stand-in driver whose every
ring-down brings one fit per probe (the probes 5 cm apart in one linear field, each frequency
that of the full potential with the neighbours' dipole fields at their coupled rest),
decomposed per probe with the coupling in the model, published per probe on /mows/sweep and
together as a latched field map.

Requirement: each probe's external field and gradient come back within 4σ of the scene's at
its place, in its own frame; the field
map holds every probe at its listed position in the stage's frame; a probe whose fits all fail
is in the map with its status and NaN, never a number.
"""

import math

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from mows_msgs.action import RotationSweep
from mows_msgs.msg import FieldMap, RingdownFit, SweepDecomposition

from mows.physics.coupling import PlacedProbe, coupled_frequencies_hz
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE as P
from mows.physics.sources import LinearGradient
from mows_ros.qos import MAP_QOS, RESULT_QOS, maps_qos
from node_processes import send_goal, serve_cycles

pytestmark = [pytest.mark.ros, pytest.mark.xdist_group("realtime")]

STD_HZ = 5e-4
ANGLES = np.radians(np.arange(0.0, 360.0, 45.0))
F00_HZ = (P.f00_hz, 125.0, 101.0)
POSITIONS_M = ((0.0, 0.0, 0.0), (0.0, 0.05, 0.0), (0.0, -0.05, 0.0))
SCENE = LinearGradient(
    np.array([[2e-3, 1e-3, 0.0], [1e-3, -3e-3, 0.0], [0.0, 0.0, 1e-3]]), field_at_origin_t=(30e-6, -20e-6, 40e-6)
)
FIELDS_T = [SCENE.field_t(np.array(r)) for r in POSITIONS_M]  # 150 µT apart: each probe's own
GRADIENT_T_PER_M = np.array([2e-3, 1e-3, -3e-3])  # Gxx, Gxy, Gyy
# A probe given by its f00 alone is the mapper's own (the paper's) with the spring of that f00.
PROBE = [P.replace(spring_nm_per_rad=P.inertia_kgm2 * ((2 * math.pi * f) ** 2 + P.damping_per_s**2)) for f in F00_HZ]
PROBES = (
    "{"
    + ", ".join(f"{k}: {{f00_hz: {f!r}, position_m: {list(r)}}}" for k, (f, r) in enumerate(zip(F00_HZ, POSITIONS_M)))
    + "}"
)


class ThreeProbeDriver:
    """Answers measurement-cycle goals with one fit per probe and ring-down."""

    def __init__(self, ros, failing=()):
        self.fits = ros.node.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        self.server = serve_cycles(ros, self.run_cycle)
        self.failing, self.cycle, self.rng = failing, 0, np.random.default_rng(4)

    def run_cycle(self, request, response):
        self.cycle += 1
        placed = [PlacedProbe(p, Pose(r, request.theta0_rad)) for p, r in zip(PROBE, POSITIONS_M)]
        frequencies = coupled_frequencies_hz(placed, SCENE)
        for repeat in range(request.repeats):
            for k, frequency in enumerate(frequencies):
                measured = float(frequency) + STD_HZ * self.rng.standard_normal()
                ok = k not in self.failing
                msg = RingdownFit(
                    cycle_id=self.cycle,
                    repeat_index=repeat,
                    probe_id=k,
                    status=RingdownFit.STATUS_OK if ok else RingdownFit.STATUS_BAD_FIT,
                    status_name="OK" if ok else "BAD_FIT",
                    theta0_rad=request.theta0_rad,
                    frequency_hz=measured if ok else math.nan,
                    frequency_std_hz=STD_HZ,
                    frequency_shift_hz=measured - F00_HZ[k] if ok else math.nan,
                    frequency_shift_std_hz=STD_HZ,
                    amplitude_rad=math.radians(2.0),
                    damping_per_s=1.8,
                    duration_s=0.5,
                )
                msg.header.stamp.sec, msg.header.stamp.nanosec = 1_763_000_000 + self.cycle, 1_000 * repeat + k
                self.fits.publish(msg)
        response.success, response.cycle_id, response.ringdowns_recorded = True, self.cycle, request.repeats
        return response


@pytest.fixture
def mapper(action_server):
    return action_server("mapper", RotationSweep, "mapper/rotation_sweep", f"probes:='{PROBES}'")  # a YAML string


def test_each_probe_is_mapped_in_its_frame_and_at_its_place(ros, mapper):
    client, _ = mapper
    ThreeProbeDriver(ros)
    sweeps, field_maps = [], []
    ros.node.create_subscription(SweepDecomposition, "mows/sweep", sweeps.append, maps_qos(3))
    _, done, feedback = send_goal(ros, client, RotationSweep.Goal(theta0_rad=ANGLES.tolist(), repeats_per_angle=2))
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    assert all(len(f.fits) == 6 for f in feedback)
    ros.wait_for(lambda: len(sweeps) == 3, "one decomposition per probe")
    assert [s.probe_id for s in sweeps] == [0, 1, 2]
    for s, field in zip(sweeps, FIELDS_T):
        assert s.status == 0 and s.header.frame_id == f"mows_rotation_plane_{s.probe_id}" and s.n_points == 16
        sigma = np.sqrt(np.diag(np.reshape(s.field_covariance_t2, (2, 2))))
        assert np.all(np.abs(np.array(s.field_t) - field[:2]) < 4 * sigma), (s.probe_id, s.field_t, field)
        sigma = np.sqrt(np.diag(np.reshape(s.gradient_covariance, (3, 3))))
        gradient = np.array(s.gradient_t_per_m)
        assert np.all(np.abs(gradient - GRADIENT_T_PER_M) < 4 * sigma), (s.probe_id, gradient)
    assert done.result.decomposition.probe_id == 0
    # /mows/sweep keeps every probe's decomposition for a subscriber that comes later.
    late = []
    ros.node.create_subscription(SweepDecomposition, "mows/sweep", late.append, maps_qos(3))
    ros.wait_for(lambda: len(late) == 3, "the latched decompositions")
    # The map is latched: a subscriber that comes after the sweep gets it.
    ros.node.create_subscription(FieldMap, "mows/field_map", field_maps.append, MAP_QOS)
    ros.wait_for(lambda: field_maps, "the latched field map")
    (field_map,) = field_maps
    assert field_map.header.frame_id == "mows_rotation_plane"
    assert [p.probe_id for p in field_map.probes] == [0, 1, 2]
    for point, s, position in zip(field_map.probes, sweeps, POSITIONS_M):
        assert tuple(point.position_m) == position and point.frame_id == s.header.frame_id
        np.testing.assert_array_equal(point.field_t, s.field_t)
        np.testing.assert_array_equal(point.gradient_covariance, s.gradient_covariance)


def test_a_probe_without_a_good_fit_is_in_the_map_without_numbers(ros, mapper):
    client, _ = mapper
    ThreeProbeDriver(ros, failing=(2,))
    field_maps = []
    ros.node.create_subscription(FieldMap, "mows/field_map", field_maps.append, MAP_QOS)
    _, done, _ = send_goal(ros, client, RotationSweep.Goal(theta0_rad=ANGLES.tolist(), repeats_per_angle=1))
    assert done.status == GoalStatus.STATUS_ABORTED and "probe 2: no successful ring-down" in done.result.message
    ros.wait_for(lambda: field_maps, "the field map")
    broken = field_maps[0].probes[2]
    assert broken.status != 0 and "no successful ring-down" in broken.message
    assert np.all(np.isnan(broken.field_t)) and np.all(np.isnan(broken.gradient_t_per_m))
    assert [p.status for p in field_maps[0].probes[:2]] == [0, 0]
