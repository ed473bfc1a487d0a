"""A model is `adequate` only when its physics is consistent too.

Statistically adequate residuals are not enough: an effect whose free fit lies more than 5σ
from its physical value, or a generic correction in the model, is reported as what it is.
"""

from lab.tables import rotation_table
from mows.lab import ProbeSet, analyse
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE

FIELD = UniformField((40e-6, 0.0, 0.0))  # 40 µT in the plane: the static deflection stays < 0.4 mHz


def _table(truth_amplitude_deg, table_amplitude_deg, seed=0):
    return rotation_table(FIELD, seed, truth_amplitude_deg, amplitude_deg=table_amplitude_deg)


def test_a_free_physical_strength_far_from_its_value_is_inconsistent_physics():
    # The table says 24°, the ring-downs swung 8°: the amplitude's weakening of the field spring
    # (≈ −A²/8 of 180 mHz at 24°, 3 mHz) is a ninth of the prediction.
    report = analyse(
        _table(8.0, 24.0), ProbeSet.one(PAPER_PROBE), effects=["finite_amplitude"], rank=False, cross_validate=False
    )
    value, std = report.effect_parameter("finite_amplitude.strength")
    assert abs(value - 1.0) > 5 * std  # the premise: the data reject strength 1
    assert report.diagnosis.structure.goodness_p > 0.005  # … while the residuals look like noise
    assert report.verdict == "inconsistent_physics"
    explanation = report.diagnosis.explanation
    assert "finite_amplitude" in explanation and "σ from its physical value" in explanation


def test_the_same_effect_at_its_physical_value_is_adequate():
    report = analyse(
        _table(24.0, 24.0), ProbeSet.one(PAPER_PROBE), effects=["finite_amplitude"], rank=False, cross_validate=False
    )
    assert report.verdict == "adequate", report.diagnosis.explanation


def test_a_generic_term_in_the_model_is_named_not_called_adequate():
    report = analyse(
        _table(24.0, 24.0),
        ProbeSet.one(PAPER_PROBE),
        effects=["finite_amplitude (at physics)", "moment_scale"],
        rank=False,
        cross_validate=False,
    )
    assert report.verdict == "needs_generic_term", report.diagnosis.explanation
    explanation = report.diagnosis.explanation
    assert "moment_scale" in explanation and "generic correction" in explanation and "β0" in explanation
