"""Workspace maps: the solid-harmonic model fitted to sweeps' B and G against the same model
fitted to a Hall-probe map, on an eight-coil navigation system.

The truth is :func:`mows.sim.navigation.navigation_system` (finite windings with errors, exact
current loops, iron cores as dipole chains; 1.5 mT at the centre); the workspace is a ball of
5 cm diameter about its centre. Sweeps (:func:`mows.workspace.simulated.simulate_sweep`: the
probe's full potential, decomposed by the sweep's own code) and Hall points (3D B, σ = 0.1 %
of |B| per component) are taken at the same nested, evenly spread positions on the ball's
boundary; each prefix is fitted with its degree chosen by cross-validation over sweeps (or
points), and predicts B and G at held-out points uniform in the ball.

Figures: for each count, the rms error of B over the rms |B| (``b_error``), of G over the rms
‖G‖ (Frobenius, ``g_error``), and the pulls' standard deviations (each component's error over
its predicted σ); the fewest sweeps, and the fewest Hall points, that reach the stated accuracy
(B ≤ ``target_b``, and for the sweeps G ≤ ``target_g``), with their minutes of robot time
(:mod:`mows.workspace.simulated`'s time model) and the ratio of points.

With the arm's pose error (:func:`pose_curve`): the maps that ignore it and that carry it, the
bound no map of the sweeps can beat, and the carried map's σ split by cause
(:func:`mows.workspace.poses.error_split`) with its truncation. :func:`levers` says, to first
order, what more sweeps or less noisy ones would give at an industrial arm's accuracy.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from mows.physics.field import FieldSource
from mows.physics.probe import PAPER_PROBE
from mows.sim.navigation import navigation_system
from mows.workspace import simulated
from mows.workspace.design import boundary_positions
from mows.workspace.fit import WorkspaceModel, choose_degree, fit
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.observations import SWEEP_COMPONENTS, Observation, gravity_field_t, plane_readout
from mows.workspace.poses import PoseError, error_split, frame_bound, map_with_pose_error, moved, pose_marginalised

RADIUS_M = 0.025
CENTRE_FIELD_T = 1.5e-3
TARGET_B = 5e-4
TARGET_G = 5e-3
DEGREES = tuple(range(2, 11))
SWEEP_COUNTS = (8, 10, 12, 15, 18, 21, 25, 30)
# The arm's accuracy, (σ per position component, m; σ per rotation component, deg): an
# industrial arm's, between, a surgical arm's (none is the sweep curve's last row).
POSE_ERRORS = ((1e-4, 0.01), (3e-4, 0.1), (1e-3, 1.0))
# Draws of each pose error: one map's pulls are correlated through its few largest pose errors,
# its B error through their mean; each figure carries its Monte Carlo σ.
POSE_DRAWS = 4
HALL_COUNTS = (20, 30, 45, 60, 80, 100, 130, 160, 200, 250, 320, 400)
# What would bring B within its goal at an industrial arm's accuracy, to first order: (sweeps,
# their noise over a sweep's): as measured, ten times less noisy (a hundred ring-downs per
# orientation), more sweeps. At the degree the carried fit chooses there.
LEVERS = ((30, 1.0), (30, 0.1), (45, 1.0), (60, 1.0))
LEVER_ERROR = (1e-4, 0.01)
LEVER_DEGREE = 7


def accuracy(model: WorkspaceModel, source: FieldSource, points_m: np.ndarray) -> dict[str, float]:
    """Held-out errors and pulls of ``model`` against ``source`` at ``points_m`` (module docstring)."""
    field, field_std = model.field_t(points_m)
    gradient, gradient_std = model.gradient_t_per_m(points_m)
    true_field, true_gradient = source.field_t(points_m), source.gradient_t_per_m(points_m)
    return {
        "b_error": float(np.sqrt(np.mean((field - true_field) ** 2) / np.mean(true_field**2))),
        "g_error": float(np.sqrt(np.mean((gradient - true_gradient) ** 2) / np.mean(true_gradient**2))),
        "b_pull_sd": float(np.std((field - true_field) / field_std)),
        "g_pull_sd": float(np.std((gradient - true_gradient) / gradient_std)),
    }


def fitted(observations: Sequence[Observation], degrees: Sequence[int]) -> WorkspaceModel:
    """The model of the cross-validated degree."""
    choice = choose_degree(observations, degrees, scale_m=RADIUS_M)
    return fit(observations, SolidHarmonics(choice.chosen, (0.0, 0.0, 0.0), RADIUS_M))


def _curve(observations, counts, degrees, source, points) -> list[dict]:
    rows = []
    for count in counts:
        model = fitted(observations[:count], degrees)
        rows.append({"count": count, "degree": model.basis.max_degree, **accuracy(model, source, points)})
    return rows


def _first(rows: list[dict], target_b: float, target_g: float | None) -> int | None:
    for row in rows:
        if row["b_error"] <= target_b and (target_g is None or row["g_error"] <= target_g):
            return int(row["count"])
    return None


def pose_curve(
    sweeps: Sequence[Observation],
    degrees: Sequence[int],
    source: FieldSource,
    points: np.ndarray,
    levels: Sequence[tuple[float, float]],
    rng: np.random.Generator,
    draws: int = 1,
) -> list[dict]:
    """For each pose error (σ_p, σ_φ in degrees), over ``draws`` draws of it: the sweeps
    reported at poses off by the draw, fitted ignoring it (``naive_*``, the degree chosen by
    the sweeps' noise alone) and carrying it (``eiv_*``, the degree chosen with it); each
    figure the rms over the draws (the pulls' sd pooled), with its Monte Carlo σ (``*_mc``),
    and ``bound_b_error``, the B error no map of these sweeps can avoid (:func:`frame_bound`)."""
    truth = source.field_t(points), source.gradient_t_per_m(points)
    rms_field, rms_gradient = math.sqrt(np.mean(np.sum(truth[0] ** 2, axis=1))), math.sqrt(np.mean(truth[1] ** 2) * 9)
    exact = exact_readings(sweeps, source)
    rows = []
    for position_std_m, angle_std_deg in levels:
        error = PoseError(position_std_m, math.radians(angle_std_deg))
        figures: dict[str, list[float]] = {}
        for _ in range(draws):
            reported = [moved(obs, rng.normal(size=6) * error.std) for obs in sweeps]
            fitted_maps = map_with_pose_error(reported, degrees, error, (0.0, 0.0, 0.0), RADIUS_M)
            naive, carried = fitted_maps.plain, fitted_maps.carried.model
            for kind, model in (("naive", naive), ("eiv", carried)):
                figures.setdefault(f"{kind}_degree", []).append(model.basis.max_degree)
                for key, value in accuracy(model, source, points).items():
                    figures.setdefault(f"{kind}_{key}", []).append(value)
            # the carried map's σ by cause, and what its weighted fit of exact readings at the
            # true poses misses (the degree's truncation)
            split = error_split(reported, carried, error, points)
            for part in split.field_t:
                figures.setdefault(f"split_{part}_b", []).append(split.field_t[part] / rms_field)
                figures.setdefault(f"split_{part}_g", []).append(split.gradient_t_per_m[part] / rms_gradient)
            truncated = accuracy(fit(pose_marginalised(exact, carried, error), carried.basis), source, points)
            figures.setdefault("truncation_b", []).append(truncated["b_error"])
            figures.setdefault("truncation_g", []).append(truncated["g_error"])
        bound = frame_bound(*truth, error, len(sweeps))
        row: dict[str, float] = {"position_std_m": position_std_m, "angle_std_deg": angle_std_deg}
        for key, values in figures.items():
            row[key] = float(np.median(values)) if key.endswith("degree") else _rms(values)
        for key, values in figures.items():
            if not key.endswith("degree") and not key.startswith(("split_", "truncation_")):
                row[f"{key}_mc"] = _monte_carlo_std(values)
        rows.append({**row, "bound_b_error": bound})
    return rows


def exact_readings(sweeps: Sequence[Observation], source: FieldSource) -> list[Observation]:
    """``sweeps`` reading ``source`` without noise at their poses (their readouts: B with the
    magnet's weight, G, and the lever's curvature)."""
    positions = np.array([obs.position_m for obs in sweeps])
    fields = source.field_t(positions), source.gradient_t_per_m(positions), source.hessian_t_per_m2(positions)
    exact = []
    for obs, field, gradient, hessian in zip(sweeps, *fields):
        r = obs.readout
        values = r.field @ field + np.einsum("pij,ij->p", r.gradient, gradient) + r.offset
        values = values + np.einsum("pijk,ijk->p", r.hessian, hessian)
        exact.append(dataclasses.replace(obs, values=values))
    return exact


def levers(
    source: FieldSource,
    covariance: np.ndarray,
    points: np.ndarray,
    rng: np.random.Generator,
    cases: Sequence[tuple[int, float]] = LEVERS,
    degree: int = LEVER_DEGREE,
    pose_error: tuple[float, float] = LEVER_ERROR,
) -> list[dict]:
    """For each (sweeps, noise scale) of ``cases``: the B error, over rms |B|, of a carried map
    of that many sweeps at new evenly spread poses with a sweep's ``covariance`` scaled, to
    first order: :func:`error_split`'s shares of its σ and the truncation of its weighted fit to
    exact readings, and their sum in squares (``b_error``)."""
    error = PoseError(pose_error[0], math.radians(pose_error[1]))
    basis = SolidHarmonics(degree, (0.0, 0.0, 0.0), RADIUS_M)
    weight = gravity_field_t(PAPER_PROBE, simulated.GRAVITY_M_PER_S2)
    rms_field = math.sqrt(np.mean(np.sum(source.field_t(points) ** 2, axis=1)))
    rows = []
    for count, scale in cases:
        template = [
            Observation(
                p.position_m,
                p.plane,
                np.zeros(5),
                scale**2 * covariance,
                plane_readout(p.plane, PAPER_PROBE.lever_m, weight),
                k,
                SWEEP_COMPONENTS,
            )
            for k, p in enumerate(simulated.random_planes(boundary_positions(count, RADIUS_M), rng))
        ]
        exact = exact_readings(template, source)
        model = fit(exact, basis)  # the pose Jacobians need B, G and H to a few per cent
        shares = {f"{k}_b": v / rms_field for k, v in error_split(exact, model, error, points).field_t.items()}
        truncation = accuracy(fit(pose_marginalised(exact, model, error), basis), source, points)["b_error"]
        total = math.sqrt(sum(v**2 for v in shares.values()) + truncation**2)
        rows.append({"sweeps": count, "noise_scale": scale, "b_error": total, **shares, "truncation_b": truncation})
    return rows


def _rms(values: Sequence[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _monte_carlo_std(values: Sequence[float]) -> float:
    """σ of the rms of ``values`` over their draws: σ(x²)/(2·rms·√n); NaN from one draw."""
    squares = np.square(values)
    if squares.size < 2:
        return math.nan
    return float(np.std(squares, ddof=1) / (2.0 * _rms(values) * math.sqrt(squares.size)))


def run(
    sweep_counts: Sequence[int] = SWEEP_COUNTS,
    hall_counts: Sequence[int] = HALL_COUNTS,
    degrees: Sequence[int] = DEGREES,
    held_out: int = 300,
    target_b: float = TARGET_B,
    target_g: float = TARGET_G,
    pose_errors: Sequence[tuple[float, float]] = POSE_ERRORS,
    pose_draws: int = POSE_DRAWS,
    lever_cases: Sequence[tuple[int, float]] = LEVERS,
    lever_degree: int = LEVER_DEGREE,
    seed: int = 0,
) -> dict:
    rng = np.random.default_rng(seed)
    source = navigation_system(CENTRE_FIELD_T, seed=seed)
    probe = PAPER_PROBE
    points = simulated.ball_points(held_out, RADIUS_M, rng)
    poses = simulated.random_planes(boundary_positions(max(sweep_counts), RADIUS_M), rng)
    sweeps = simulated.sweep_observations(
        [simulated.simulate_sweep(source, p, probe, rng) for p in poses], poses, probe
    )
    hall = simulated.simulate_hall(source, boundary_positions(max(hall_counts), RADIUS_M), rng)
    sweep_rows = _curve(sweeps, sweep_counts, degrees, source, points)
    hall_rows = _curve(hall, hall_counts, degrees, source, points)
    sweeps_needed = _first(sweep_rows, target_b, target_g)
    hall_needed = _first(hall_rows, target_b, None)
    sweep_s, hall_s = simulated.sweep_seconds(), simulated.MOVE_S + simulated.HALL_POINT_S
    last = sweep_rows[-1]
    poses_rows = pose_curve(sweeps, degrees, source, points, pose_errors, rng, pose_draws)
    covariance = np.mean([obs.covariance for obs in sweeps], axis=0)
    lever_rows = levers(source, covariance, points, np.random.default_rng(seed + 1), lever_cases, lever_degree)
    return {
        "sweeps": last["count"],
        "degree": last["degree"],
        "b_error": last["b_error"],
        "g_error": last["g_error"],
        "b_pull_sd": last["b_pull_sd"],
        "g_pull_sd": last["g_pull_sd"],
        "hall_points": hall_rows[-1]["count"],
        "hall_b_error": hall_rows[-1]["b_error"],
        "hall_b_pull_sd": hall_rows[-1]["b_pull_sd"],
        "sweeps_needed": sweeps_needed if sweeps_needed is not None else math.nan,
        "hall_points_needed": hall_needed if hall_needed is not None else math.nan,
        "points_ratio": hall_needed / sweeps_needed if sweeps_needed and hall_needed else math.nan,
        "sweep_minutes": sweeps_needed * sweep_s / 60.0 if sweeps_needed else math.nan,
        "hall_minutes": hall_needed * hall_s / 60.0 if hall_needed else math.nan,
        "sweep_curve": [[r["count"], r["degree"], r["b_error"], r["g_error"]] for r in sweep_rows],
        "hall_curve": [[r["count"], r["degree"], r["b_error"], r["g_error"]] for r in hall_rows],
        "pose_curve_columns": list(poses_rows[0]) if poses_rows else [],
        "pose_curve": [list(row.values()) for row in poses_rows],
        **(_pose_figures(poses_rows[-1]) if poses_rows else {}),
        "levers_columns": list(lever_rows[0]) if lever_rows else [],
        "levers": [list(row.values()) for row in lever_rows],
    }


def _pose_figures(row: dict) -> dict:
    """The largest pose error's figures, at the top level."""
    keys = ("b_error", "g_error", "b_pull_sd", "g_pull_sd")
    return {f"pose_{kind}_{key}": row[f"{kind}_{key}"] for kind in ("naive", "eiv") for key in keys}
