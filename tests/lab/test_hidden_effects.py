"""Tables with one hidden physical effect, from independent physics (exact sources through
mows.physics.potential, see mows.lab.data.synthetic): the lab must name the effect, add it, and recover it.

Every table but the strong-field one uses a small ring-down amplitude (2°): at the usual 24°
the finite-amplitude readout is itself a hidden effect of a few tenths of a mHz, which biases
the others' parameters by more than 2σ (the lab finds it at strong fields, see below).
"""

import math

import numpy as np
import pytest

from mows.lab import ProbeSet, analyse
from mows.lab.data import synthetic
from mows.physics.field import CurrentLoop, UniformField, anti_helmholtz_pair, helmholtz_pair
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE

EARTH = UniformField((15e-6, -12e-6, -40e-6))
SMALL_AMPLITUDE_DEG = 2.0
HELMHOLTZ_T_PER_A_TURN = 8.562e-6  # centre field of the paper's pair (R = spacing = 10.5 cm)


def rotation_table(source, seed, **options):
    sweep = synthetic.rotation_sweeps(10.0, 2)
    theta0 = sweep.pop("theta0_deg")
    options.setdefault("amplitude_deg", SMALL_AMPLITUDE_DEG)
    return synthetic.synthesize(PAPER_PROBE, source, theta0, np.random.default_rng(seed), **sweep, **options)


def value_and_std(report, name):
    # An effect held at its physical value is checked through its free fit with the rest.
    return report.effect_parameter(name)


def assert_named_and_recovered(table, effect, truths, sigmas=2.0):
    first = analyse(table, ProbeSet.one(PAPER_PROBE), cross_validate=False)
    best = first.candidates[0]
    group = [c.name for c in first.candidates if best.group and c.group == best.group]
    assert best.name == effect or effect in group, [c.name for c in first.candidates[:4]]
    assert first.verdict == "effect_missing"
    final = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert effect in final.effect_names
    assert final.chi2_dof <= 1.5
    for parameter, truth in truths.items():
        value, std = value_and_std(final, f"{effect}.{parameter}")
        assert abs(value - truth) <= sigmas * std, (parameter, value, std, truth)
    return first, final


def test_gravity_of_a_tilted_plane_is_found_with_its_degenerate_partners():
    tilt, azimuth = math.radians(2.0), math.radians(30.0)
    table = rotation_table(EARTH, 1, gravity_m_per_s2=Pose.tilted(tilt, azimuth).gravity_m_per_s2)
    truth = {"down_x": -math.sin(tilt) * math.sin(azimuth), "down_y": math.sin(tilt) * math.cos(azimuth)}
    first, final = assert_named_and_recovered(table, "gravity", truth)
    # Gravity and an unreferenced field act identically on the lever: one group, and the lab
    # says that no variation of the rotation data separates them.
    group = next(g for g in first.groups if "gravity" in g.members)
    assert "field_offset" in group.members
    assert any(check.startswith("gravity:") for check in group.checks)
    assert final.history[0].chi2_dof > 100 > final.history[-1].chi2_dof


def test_transverse_gradient_of_an_anti_helmholtz_pair():
    pair = anti_helmholtz_pair((0, 0, 0), (1, 0, 0), 0.105, 100, 1.0)  # ≈ 10 mT/m, like the paper's
    assert_named_and_recovered(rotation_table(pair + EARTH, 2), "transverse_gradient", {"strength": 1.0})


def test_thermal_drift_follows_the_temperature():
    sweep = synthetic.rotation_sweeps(10.0, 2)
    t = sweep["t_s"]
    temperature = 293.15 + 1.5 * (1 - np.exp(-t / 300.0)) + 0.3 * np.sin(2 * np.pi * t / 200.0)
    table = rotation_table(EARTH, 3, temperature_k=temperature)
    assert_named_and_recovered(table, "thermal_drift", {"spring_temp_coeff_per_k": PAPER_PROBE.spring_temp_coeff_per_k})


def test_finite_amplitude_in_a_strong_field_sweep_along_the_axis():
    # Fig. 3 of the paper: the field of a Helmholtz pair along x', ±5 mT, at θ0 = 0° and 180°,
    # ring-downs started at 24° and at 12° (which separates it from a calibration error of β0).
    rows = [
        (b, angle, amplitude)
        for b in np.linspace(-5e-3, 5e-3, 11)
        for angle in (0.0, 180.0)
        for amplitude in (24.0, 12.0)
    ]
    field, angle, amplitude = (np.array(column) for column in zip(*rows))
    current = field / (HELMHOLTZ_T_PER_A_TURN * 100)
    sources = [helmholtz_pair((0, 0, 0), (1, 0, 0), 0.105, 100, i) + EARTH for i in current]
    table = synthetic.synthesize(
        PAPER_PROBE,
        sources,
        angle,
        np.random.default_rng(0),
        amplitude_deg=amplitude,
        coil_current_a=current,
        sweep=np.arange(len(rows)) % 4,
    )
    assert_named_and_recovered(table, "finite_amplitude", {"strength": 1.0})


def test_a_nearby_coil_brings_transverse_gradient_then_curvature():
    loop = CurrentLoop((0.025, 0.01, 0.0), (1, 0, 0), 0.008, 50, 0.3)
    first, final = assert_named_and_recovered(rotation_table(loop + EARTH, 0), "transverse_gradient", {"strength": 1.0})
    assert "field_curvature" in final.effect_names
    hessian = loop.hessian_t_per_m2(np.zeros(3))
    # The curvature's truth is the loop's in-plane Hessian; terms of third order along the arc
    # (l/d ≈ 8 %, in no catalog effect) bias it slightly, hence 3σ.
    for name, index in (("hxxx", (0, 0, 0)), ("hxxy", (0, 0, 1)), ("hxyy", (0, 1, 1)), ("hyyy", (1, 1, 1))):
        value, std = value_and_std(final, f"field_curvature.{name}_t_per_m2")
        assert abs(value - hessian[index]) <= 3 * std, (name, value, std, hessian[index])


@pytest.fixture(scope="module")
def control_truth():
    sweep = synthetic.rotation_sweeps(10.0, 2)
    theta0 = sweep.pop("theta0_deg")
    truth = synthetic.true_frequency_hz(PAPER_PROBE, EARTH, np.radians(theta0), math.radians(SMALL_AMPLITUDE_DEG))
    return theta0, sweep, truth


def test_control_without_hidden_effect_is_adequate_and_false_alarms_are_rare(control_truth):
    """The issue's bound: at most 1 false alarm in 40 seeds, and --auto adds nothing to any
    control. Measured: seed 126 ends `unexplained_structure` (1 in 40); --auto added no effect
    to any of the 40."""
    theta0, sweep, truth = control_truth
    verdicts, added = [], []
    for seed in range(40):
        table = synthetic.synthesize(
            PAPER_PROBE,
            EARTH,
            theta0,
            np.random.default_rng(100 + seed),
            truth_hz=truth,
            amplitude_deg=SMALL_AMPLITUDE_DEG,
            **sweep,
        )
        verdicts.append(analyse(table, ProbeSet.one(PAPER_PROBE), cross_validate=False).verdict)
        added += analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False).effect_names
    assert verdicts.count("adequate") >= 39, verdicts
    assert added == [], added


def test_structure_no_effect_explains_is_described_not_forced(control_truth):
    theta0, sweep, truth = control_truth
    # A 4θ0 pattern of 2 mHz (e.g. a magnetometer cross-talk) is in no catalog effect.
    table = synthetic.synthesize(
        PAPER_PROBE,
        EARTH,
        theta0,
        np.random.default_rng(7),
        amplitude_deg=SMALL_AMPLITUDE_DEG,
        truth_hz=truth + 2e-3 * np.cos(4 * np.radians(theta0)),
        **sweep,
    )
    report = analyse(table, ProbeSet.one(PAPER_PROBE), cross_validate=False)
    assert report.verdict == "unexplained_structure"
    assert "harmonic 4" in report.structure
