"""Alias groups over the whole catalog, exact aliases in words and numbers, physics preferred.

Truth from exact physics (mows.lab.data.synthetic). A constant finite amplitude A scales the field spring
like a moment-scale error ε = ⟨2·J1(A)/A⟩ − 1 ≈ −A²/8 (−0.86 % at 15°; less over a decaying
ring-down); gravity with in-plane downward part d acts like a field (a·g·l/m)·d, 154 µT·d for
the paper's probe.
"""

import math

import numpy as np
import pytest

from mows.lab import ProbeSet, analyse, catalog, diagnose
from mows.lab.data import synthetic
from mows.lab.diagnosis.physical_aliases import amplitude_scale_error, gravity_field_t
from mows.lab.selection.stepwise import prefer_physical
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE


def _amplitude_table(seed=0):
    """20 µT in the plane, ring-downs from 15°: the amplitude's weakening of the field spring
    (≈ 0.5 mHz) at 0.1 mHz noise; the static deflection stays below 0.1 mHz."""
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = sweep.pop("theta0_deg")
    return synthetic.synthesize(
        PAPER_PROBE,
        UniformField((20e-6, 0.0, 0.0)),
        theta0,
        np.random.default_rng(seed),
        f_std_hz=1e-4,
        amplitude_deg=15.0,
        **sweep,
    )


def test_the_probe_constants_give_the_documented_alias_sizes():
    assert gravity_field_t(PAPER_PROBE) == pytest.approx(154e-6, rel=0.01)
    a = math.radians(15.0)
    epsilon, _ = amplitude_scale_error(_amplitude_table(), ProbeSet.one(PAPER_PROBE))
    # Over the ring-down the amplitude decays from 15°: between none and the start's −A²/8.
    assert -(a**2) / 8 < epsilon < 0


def test_a_generic_term_in_the_model_is_grouped_with_the_physics_it_absorbs_and_replaced_by_it():
    table = _amplitude_table()
    held = analyse(table, ProbeSet.one(PAPER_PROBE), effects=["moment_scale"], cross_validate=False)
    # finite_amplitude is absorbed by the moment scale …
    group = next(g for g in held.groups if g.in_model == ["moment_scale"])
    assert "finite_amplitude" in group.members  # … and reported as its alias, with numbers
    alias = next(a for a in group.aliases if a.startswith("finite_amplitude ≡ moment_scale"))
    epsilon, _ = amplitude_scale_error(table, ProbeSet.one(PAPER_PROBE))
    assert f"{epsilon * 100:.3g} %" in alias and "here moment_scale ε" in alias
    value, std = held.effect_parameter("moment_scale.scale_error")
    assert abs(value - epsilon) < 3 * std  # the premise: the two are the same number
    # The lab replaces the generic term by the physics of known size that fits as well, and says why.
    found = diagnose(held.fit, catalog().values(), ProbeSet.one(PAPER_PROBE))
    history = []
    preferred = prefer_physical(
        found, list(catalog().values()), ProbeSet.one(PAPER_PROBE), history, cross_validate=False
    )
    assert preferred.fit.model.labels == ["finite_amplitude (at physics)"]
    change = history[-1].change
    assert change.startswith("replace moment_scale by finite_amplitude (at physics): they fit alike")
    assert "generic correction" in change and "finite_amplitude ≡ moment_scale" in change
    # --auto ends with known physics only (the truth's small static deflection joins it).
    auto = analyse(table, ProbeSet.one(PAPER_PROBE), effects=["moment_scale"], auto=True, cross_validate=False)
    assert "finite_amplitude (at physics)" in auto.effects and not any(e.generic for e in auto.fit.model.effects)
    assert auto.verdict == "adequate", auto.diagnosis.explanation


def test_gravity_in_the_model_is_grouped_with_the_field_offset_it_absorbs():
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = sweep.pop("theta0_deg")
    tilt = math.radians(2.0)
    table = synthetic.synthesize(
        PAPER_PROBE,
        UniformField((20e-6, -10e-6, -40e-6)),
        theta0,
        np.random.default_rng(1),
        gravity_m_per_s2=Pose.tilted(tilt).gravity_m_per_s2,
        amplitude_deg=2.0,
        **sweep,
    )
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert "gravity" in report.effect_names
    group = next(g for g in report.groups if g.in_model == ["gravity"])
    assert {"field_offset", "plane_tilt"} <= set(group.members)
    alias = next(a for a in group.aliases if a.startswith("gravity ≡ field_offset"))
    down_x, _ = report.effect_parameter("gravity.down_x")
    down_y, _ = report.effect_parameter("gravity.down_y")
    scale_ut = gravity_field_t(PAPER_PROBE) * 1e6
    assert "154 µT" in alias and f"({scale_ut * down_x:.3g}, {scale_ut * down_y:.3g}) µT" in alias
