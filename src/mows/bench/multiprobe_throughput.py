"""Map points per minute of device time with one probe and with several probes excited together.

A map point is one probe's in-plane field and gradient decomposed to the target σ (the same
target per component for every probe). Both cases run the driver's cycle in device time
(:class:`mows.bench.rig.DeviceTimeRig`: turn, settle, excite; the estimator's fit) in the
``three_probes`` scene: the probe alone rings no other and is driven to the stop, tuned
(``ALONE_TUNING_STEPS``), the probes together share a multi-tone drive at their f00, untuned;
round after round of ``points`` orientations on the shared stage, and decompose every probe
with the coupling in the model (:func:`mows.sweep.probes.decompose_probes`) after every point
from the one that gives the sweep the orientations its model needs (7 for the field's 3θ0
curvature, or all ``points`` when fewer), until every probe reaches the target or
``max_sweeps`` rounds have run. Probes that reached the target are measured on with the others:
their points cost nothing extra. One probe is the scene with only ``single`` of its probes (by
default the paper's 112.5 Hz one); several are all of them. Points per minute = probes × 60 /
device seconds, NaN when the target was not reached (the reason is reported).

Several probes cost no more excitation time than one measured ring-down of one (their tones sum
in one group) and skip its tuning ring-downs, so the ratio of several to one is the number of
probes times the time a point of one takes over a point of the group, divided by how much
longer the slowest probe of the group needs than the single one (docs/multi_probe.md).
"""

from __future__ import annotations

import math

import numpy as np

from mows.bench.rig import ONE_ROUND, DeviceTimeRig
from mows.device.cycle.phases import CycleRequest
from mows.sim.scenario import load_scenario
from mows.sweep.decompose import unknown_count
from mows.sweep.planner import PrecisionGoal, achieved_std, reached
from mows.sweep.probes import decompose_probes, sweeps_of

SCENARIO = "three_probes"
SINGLE_PROBE = 1  # the paper's f00
ALONE_TUNING_STEPS = 2  # the probe alone is tuned before each measured ring-down, the driver's default


def time_to_target(scenario, goal: PrecisionGoal, points: int, max_sweeps: int, seed: int, tuning_steps: int) -> dict:
    """Sweeps of ``scenario``'s probes, each cycle with ``tuning_steps``, until every probe
    reaches ``goal``: the figures."""
    rig = DeviceTimeRig(scenario, ONE_ROUND, seed=seed)
    placed = scenario.placed_probes()
    first_check = min(points, unknown_count(curvature=True))
    fits: list = []
    decompositions: list = []
    for j in range(points * max_sweeps):
        fits.append(rig.run_cycle(CycleRequest(2.0 * np.pi * j / points, tuning_steps=tuning_steps)).fits)
        if len(fits) < first_check:
            continue
        decompositions = decompose_probes(sweeps_of(placed, fits, scenario.sensors.pair))
        if all(reached(goal, d) for d in decompositions):
            break
    done = bool(decompositions) and all(reached(goal, d) for d in decompositions)
    return {
        "probes": len(placed),
        "device_s": rig.time_s,
        "points": len(fits),
        "reached": done,
        "message": "target reached" if done else f"not reached in {max_sweeps} rounds of {points} points",
        "points_per_minute": len(placed) * 60.0 / rig.time_s if done else math.nan,
        "std_per_probe": [achieved_std(d).tolist() for d in decompositions],
    }


def run(
    goal: PrecisionGoal,
    points: int = 8,
    max_sweeps: int = 6,
    single: int = SINGLE_PROBE,
    seed: int = 1,
) -> dict:
    """Points per minute with probe ``single`` alone and with every probe of the scene."""
    scene = load_scenario(SCENARIO)
    alone = scene.probes[single]
    alone_scene = scene.replace(probes=(alone,))
    one = time_to_target(alone_scene, goal, points, max_sweeps, seed, ALONE_TUNING_STEPS)
    every = time_to_target(scene, goal, points, max_sweeps, seed, 0)
    return {
        "scenario": SCENARIO,
        "single_probe": single,
        "one": one,
        "all": every,
        "ratio": every["points_per_minute"] / one["points_per_minute"],
    }
