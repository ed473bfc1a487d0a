"""The start swing from physics, and our own tables with impossible per-fit amplitudes.

Requirement: every ring-down starts at the housing stop, so its swing turns θstop − |θs| from
the rest angle (its first harmonic, what a fit reports, lies up to 1 % beyond); in a strong
field the lab must model the finite amplitude from there, not from an ``amplitude_deg`` that
single fits got wrong, and it must read (not refuse) the table that ``mows fit --csv`` wrote
with such values. The truth's rest angle comes from minimising the exact arc energy
(:func:`mows.physics.potential.arc_energy_j`) with scipy, independently of the lab's Newton
iteration on its Chebyshev potential.
"""

import math

import numpy as np
import pytest
import scipy.optimize

from mows.lab import FrequencyModel, ProbeSet, TableError, catalog, load_table
from mows.lab.data import synthetic
from mows.lab.data.intake import tool_table
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential, arc_energy_j
from mows.physics.probe import PAPER_PROBE

FIELD_T = (3.4e-3, 0.0, 0.0)  # the issue's ±2 A calibration supply along x
NOISE_HZ = 1e-3
WRONG_POOL_DEG = 8.0  # what pooling over-confident single fits gave where every swing began at the stop
BAD_ROWS = {3: -0.08, 17: math.nan}  # a subtracted wrong ε, a fit that did not determine θmax


def rest_angle_rad(theta0_rad: float) -> float:
    """θs minimising ½·kM·θ² + W(θ) over the arc, by scipy's bounded scalar minimiser."""
    source, pose = UniformField(FIELD_T), Pose(theta0_rad=theta0_rad)

    def energy(theta):
        return 0.5 * PAPER_PROBE.spring_nm_per_rad * theta**2 + float(arc_energy_j(PAPER_PROBE, source, pose, theta))

    return scipy.optimize.minimize_scalar(energy, bounds=(-0.7, 0.7), method="bounded", options={"xatol": 1e-10}).x


def first_harmonic_from_stop_rad(theta0_rad: float) -> float:
    """The first harmonic of the swing that turns at the stop on the side of θs (the fit's θmax),
    in the exact potential of the source (checked against an integrated swing in
    tests/physics/test_potential.py)."""
    rest = rest_angle_rad(theta0_rad)
    potential = ArcPotential.from_source(PAPER_PROBE, UniformField(FIELD_T), Pose(theta0_rad=theta0_rad))
    return float(potential.first_harmonic_rad(math.copysign(PAPER_PROBE.theta_stop_rad - abs(rest), rest)))


@pytest.fixture(scope="module")
def columns():
    """Two sweeps every 15° in 3.4 mT: true ring-downs from the stop, the column as pooled fits had it."""
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = np.radians(sweep["theta0_deg"])
    start = np.array([first_harmonic_from_stop_rad(t) for t in theta0])
    truth = synthetic.true_frequency_hz(PAPER_PROBE, UniformField(FIELD_T), theta0, start)
    table = synthetic.synthesize(
        PAPER_PROBE, UniformField(FIELD_T), sweep.pop("theta0_deg"), np.random.default_rng(3), NOISE_HZ, truth_hz=truth
    )
    amplitude = np.full(len(table), WRONG_POOL_DEG)
    for row, value in BAD_ROWS.items():
        amplitude[row] = value
    return {**table.columns, "amplitude_deg": amplitude, **sweep}, np.degrees(start)


def physics_model():
    held = [catalog()[name].at_physics() for name in ("static_deflection", "finite_amplitude")]
    return FrequencyModel(ProbeSet.one(PAPER_PROBE)) + held[0] + held[1]


def test_the_truth_swings_far_less_than_the_stop_at_the_deflected_rows(columns):
    _, start_deg = columns
    assert start_deg.min() < 15.0 < 23.9 < start_deg.max()  # the rest offsets reach ~10° at θ0 = 90°


def test_our_table_is_read_with_its_impossible_rows_named_and_fits_from_the_stop(columns, tmp_path):
    values, _ = columns
    path = tmp_path / "fits.csv"
    tool_table(values, "mows fit").to_csv(path)
    table = load_table(path)
    assert len(table) == len(values["f_hz"])  # nothing lost: the stop gives the bad rows their swing
    assert any("rows 4, 18" in note and "amplitude_deg" in note for note in table.notes), table.notes
    assert any("stop less the deflection" in note for note in table.notes), table.notes
    fit = physics_model().fit(table)
    assert fit.chi2_dof <= 1.5, fit.chi2_dof


def test_an_external_table_with_the_same_values_is_refused_naming_the_rows(columns):
    values, _ = columns
    with pytest.raises(TableError, match="amplitude_deg.*row"):
        load_table(values)


def test_taking_the_pooled_column_at_its_word_fails(columns):
    """The naive reading: the same table without the bad rows, its 8° column trusted."""
    values, _ = columns
    keep = np.isin(np.arange(len(values["f_hz"])), list(BAD_ROWS), invert=True)
    table = load_table({name: column[keep] for name, column in values.items()})
    assert physics_model().fit(table).chi2_dof > 20.0


def test_our_rows_with_an_impossible_frequency_are_left_out_with_a_note(columns):
    values, _ = columns
    frequency = values["f_hz"].copy()
    frequency[5] = math.nan
    table = tool_table({**values, "f_hz": frequency}, "mows fit")
    assert len(table) == len(frequency) - 1
    assert any("left out row 6 " in note and "f_hz" in note for note in table.notes), table.notes
    with pytest.raises(TableError, match="f_hz.*row 6 "):
        load_table({**values, "f_hz": frequency, "amplitude_deg": np.full(len(frequency), 20.0)})
