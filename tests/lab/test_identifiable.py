"""Numbers the table cannot determine are reported as "not identifiable", never printed.

Two orientations cannot separate a harmonic's amplitude from its phase; gravity and an
tilt of the rotation plane act identically on the lever when the reference's Bz is constant
(only their sum is determined); a temperature coefficient is determined only by the sweep in which the
temperature changed, so leaving that sweep out cannot predict it.
"""

import math

import numpy as np

from lab.tables import tilted_table
from mows.cli.main import main
from mows.lab import FrequencyModel, ProbeSet, analyse, catalog
from mows.lab.data import synthetic
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE


def test_harmonics_from_two_orientations_are_not_identifiable(tmp_path, capsys):
    theta0 = np.tile([0.0, 45.0], 20)
    table = synthetic.synthesize(PAPER_PROBE, UniformField((3e-5, 1e-5, 0.0)), theta0, np.random.default_rng(2))
    path = tmp_path / "two_angles.csv"
    table.to_csv(path)
    assert main(["lab", "compare", str(path)]) == 0
    out = capsys.readouterr().out
    section = out.split("harmonic   amplitude")[1].split("\n")[1:6]
    assert [line.split()[0] for line in section] == ["0", "1", "2", "3", "4"]
    assert all("not identifiable from these angles" in line or "absorbed by the model" in line for line in section)
    assert "not identifiable from these angles" in "".join(section) and "±" not in "".join(section)


def test_exact_aliases_leave_their_parameters_not_identifiable():
    table = tilted_table()
    effects = catalog()
    both = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["plane_tilt"] + effects["field_offset"]).fit(table)
    assert both.identifiable.tolist() == [True, False, False, False, False]
    text = both.report()
    assert text.count("not identifiable from this table") == 4 and "f00_hz" in text
    alone = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["field_offset"]).fit(table)
    assert alone.identifiable.all()


def test_a_cv_error_that_one_sweep_alone_determines_is_not_identifiable(capsys):
    sweep = synthetic.rotation_sweeps(30.0, 2, seconds_per_row=60.0)
    theta0 = sweep.pop("theta0_deg")
    # The temperature changes only in the second sweep: the first alone cannot determine α.
    temperature = np.where(sweep["sweep"] == 0, 296.0, 296.0 + 4.0 * np.linspace(0.0, 1.0, len(theta0)))
    table = synthetic.synthesize(
        PAPER_PROBE,
        UniformField((3e-5, 0.0, 0.0)),
        theta0,
        np.random.default_rng(4),
        temperature_k=temperature,
        **sweep,
    )
    report = analyse(table, ProbeSet.one(PAPER_PROBE), effects=["thermal_drift"], rank=False)
    base, drift = report.history
    assert base.cv_identifiable and math.isfinite(base.cv_rms_hz)
    assert not drift.cv_identifiable and math.isnan(drift.cv_rms_hz)
    assert drift.cv_text == "not identifiable from these sweeps"
    assert report.to_dict()["history"][1]["cv_rms"] is None


def test_a_bad_model_on_well_sampled_sweeps_still_has_a_cv_error():
    """The misfit (Birge-inflated σ) is not missing information: the base model of a tilted
    plane (χ²/dof above 5000, as in the demo) is still cross-validated."""
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = sweep.pop("theta0_deg")
    table = synthetic.synthesize(
        PAPER_PROBE,
        UniformField((2e-5, -1e-5, 0.0)),
        theta0,
        np.random.default_rng(5),
        gravity_m_per_s2=Pose.tilted(math.radians(20.0)).gravity_m_per_s2,
        **sweep,
    )
    base = analyse(table, ProbeSet.one(PAPER_PROBE), rank=False).history[0]
    assert base.chi2_dof > 5000
    assert base.cv_identifiable and math.isfinite(base.cv_rms_hz)
