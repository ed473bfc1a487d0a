"""The swing a sweep's model gives each ring-down at its first fitted sample, against an
independent integration of the lever released at the housing stop.

Truth: J·θ'' + 2Jδ·θ' + kM·θ − m·(By'·cos θ − Bx'·sin θ) = 0 (a uniform field, written out, not
through the potential's series) by solve_ivp from rest at the stop, and the first harmonic of
θ(t) over the one cycle centred on the first fitted sample (its decay within the cycle changes it
by (δT)²/24 ≈ 1e-5 of itself).
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE
from mows.sweep.shift_model import Ringdowns

# The first fitted sample after the switch-off: the estimator skips 3 ms; 10 ms puts a whole cycle
# before it, for the truth's first harmonic, and makes the loss 1.8 %.
AFTER_S = 0.01


def integrated_swing_rad(field_t, stop_rad: float, at_s: float) -> tuple[float, float]:
    """(first harmonic of the free swing at ``at_s`` after release from the stop, its rest angle)."""
    p = PAPER_PROBE
    bx, by = field_t

    def rhs(_, y):
        torque = p.spring_nm_per_rad * y[0] - p.moment_am2 * (by * math.cos(y[0]) - bx * math.sin(y[0]))
        return [y[1], -2.0 * p.damping_per_s * y[1] - torque / p.inertia_kgm2]

    rest = float(ArcPotential.from_local_field(p, np.array([bx, by, 0.0])).rest_angle_rad())
    start = math.copysign(stop_rad, rest)  # the nearer stop
    span = (0.0, at_s + 0.02)
    solution = solve_ivp(rhs, span, [start, 0.0], method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True)
    # the period from the turning points on the stop's side either side of at_s
    t = np.linspace(*span, 200_001)
    theta = solution.sol(t)[0] * math.copysign(1.0, rest)
    peaks = t[1:-1][(theta[1:-1] > theta[:-2]) & (theta[1:-1] >= theta[2:])]
    period = float(np.diff(peaks).mean())
    cycle = np.linspace(at_s - period / 2, at_s + period / 2, 4001)
    phase = np.exp(-2j * math.pi * (cycle - at_s) / period)
    samples = solution.sol(cycle)[0]
    harmonic = 2.0 * np.trapezoid(samples * phase, cycle) / period
    return abs(harmonic), rest


@pytest.mark.parametrize("theta0_deg", [0.0, 60.0, 90.0])
def test_the_swing_at_the_first_fitted_sample_has_decayed_since_the_stop(theta0_deg):
    """3.4 mT: released at 24°, the swing has lost δ·10 ms = 1.8 % (0.2°–0.4°) by the first
    fitted sample. The model's swing there matches the integration to 0.2 % of that loss at
    θ0 = 0°; at the deflected rest angles of 60° and 90° (−9.8°, −12.4°) it leaves 4 % and 6 % of
    it (the decay of a lopsided swing is not quite e^(−δt)); without the decay, 100 %."""
    field = 3.4e-3 * np.array([math.cos(math.radians(theta0_deg)), -math.sin(math.radians(theta0_deg))])
    stop = PAPER_PROBE.theta_stop_rad
    truth, rest = integrated_swing_rad(field, stop, AFTER_S)
    potential = ArcPotential.from_local_field(PAPER_PROBE, np.array([*field, 0.0]))
    damping = np.array([PAPER_PROBE.damping_per_s])
    at_stop = float(Ringdowns(stop, damping, np.array([0.5])).released_swing_rad(potential)[0])
    released = Ringdowns(stop, damping, np.array([0.5]), start_offset_s=np.array([AFTER_S]))
    model = float(released.released_swing_rad(potential)[0])
    loss = at_stop - truth
    assert abs(model - truth) < 0.1 * loss, (math.degrees(rest), math.degrees(model), math.degrees(truth))
