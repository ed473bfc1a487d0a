"""A ring-down fit through the estimator's message and back into the mapper's sweep point:
the pickup series the fit used reaches the decomposition exactly (its averaging kernel is
built from it, mows.physics.ringdown_average), and a message without one (an older bag)
gives an empty series, which the decomposition reads as Eq. S11."""

import math

import numpy as np
import pytest
from mows_msgs.msg import RingdownFit as RingdownFitMsg

from mows.estimate.axis import estimate_along_axis
from mows.estimate.ringdown import FitOptions, fit_ringdown
from mows.estimate.segments import RingdownWindow
from mows.estimate.stream import Estimated
from mows.sim.scenario import load_scenario
from mows.sweep.record import SweepPoint, SweepRecord
from mows_estimator.messages import fit_to_msg

pytestmark = pytest.mark.ros


def lever_aware_fit(scenario, theta0_rad):
    t = np.arange(10_000) / 20_000.0
    x = 0.4 * np.exp(-1.8 * t) * np.cos(2 * np.pi * 112.0 * t)
    signal = -1e-6 * np.sin(theta0_rad + x) + np.random.default_rng(2).normal(0.0, 1e-9, t.size)
    options = FitOptions.lever_aware(scenario.sensors.pair, scenario.probe, theta0_rad, max_chi2_dof=math.inf)
    fit = fit_ringdown(signal, 20_000.0, theta0_rad, 112.0, options=options)
    assert fit.ok, fit.report()
    return fit


def test_the_fits_pickup_series_reaches_the_sweep_point_exactly():
    scenario = load_scenario("anti_helmholtz")
    fit = lever_aware_fit(scenario, math.radians(90.0))
    estimate = estimate_along_axis(fit, scenario.probe, scenario.probe.f00_hz)
    window = RingdownWindow(1_000_000_000, 0.5, cycle_id=3, theta0_rad=fit.theta0_rad)
    msg = fit_to_msg(Estimated(window, fit, estimate), "mows_probe")
    point = SweepPoint.from_message(msg)
    assert len(fit.pickup) == 7 and point.pickup == fit.pickup
    record = SweepRecord([point, point])
    np.testing.assert_array_equal(record.pickups(), np.array([fit.pickup, fit.pickup]))


def test_a_message_without_a_pickup_series_leaves_the_averaging_to_eq_s11():
    msg = RingdownFitMsg(theta0_rad=0.5, frequency_hz=112.0, frequency_std_hz=1e-3, status_name="OK")
    point = SweepPoint.from_message(msg)
    assert point.pickup == ()
    assert SweepRecord([point]).pickups() is None
