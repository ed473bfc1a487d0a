"""When no catalog effect explains the residual, the lab says so, shows what the residual follows
(covariates and products of two) and sketches the plugin (issue 11, Deliver 5, in part)."""

import numpy as np

from mows.lab import analyse, synth
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE


def test_a_hidden_current_times_temperature_term_is_pointed_at():
    sweep = synth.rotation_sweeps(15.0, 4)
    theta0 = sweep.pop("theta0_deg")
    rng = np.random.default_rng(0)
    current = np.repeat([0.0, 1.0, 2.0, 3.0], 24)
    temperature = 296.0 + rng.uniform(-1.0, 1.0, len(theta0))  # not a drift in time: uncorrelated with t_s
    table = synth.synthesize(
        PAPER_PROBE,
        UniformField((2e-5, 0.0, 0.0)),
        theta0,
        rng,
        coil_current_a=current,
        temperature_k=temperature,
        **sweep,
    )
    # No catalog effect is a frequency term ∝ I·ΔT (4 mHz per A·K).
    hidden = 0.004 * (current - current.mean()) * (temperature - temperature.mean())
    report = analyse(table.with_columns(f_hz=table.f_hz + hidden), PAPER_PROBE, auto=True, cross_validate=False)
    assert report.verdict == "unexplained_structure"
    explanation = report.diagnosis.explanation
    assert "The residual follows temperature_k·coil_current_a (correlation +0.9" in explanation
    assert '@effect(name="my_effect"' in explanation
    assert "(rows.coil_current_a - rows.coil_current_a.mean())" in explanation
