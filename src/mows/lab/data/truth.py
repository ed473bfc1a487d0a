"""A sweep's decomposition against the truth of its simulated scene: each probe's in-plane
field and gradient (Bx, By, Gxx, Gxy, Gyy) with its σ, the truth at its magnet and the pull
(value − truth)/σ, and the pulls over all of them.

The truth is what a rotation sweep determines (:func:`mows.lab.data.reference.swept_reference_at`):
the field at the magnet's rest position plus (l²/4)·∂²(Bx, By)/∂z², the part of the field's
curvature over the lever's arc that turns with θ0 as the field does, and the gradient there.
A calibrated σ gives pulls of mean square 1, about 95 % of them within 2σ.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

from mows.lab.data.reference import swept_reference_at
from mows.sim.scenario import Scenario

QUANTITIES = ("bx_t", "by_t", "gxx_t_per_m", "gxy_t_per_m", "gyy_t_per_m")
WITHIN_SIGMAS = 2.0  # a component this many σ from the truth or closer counts as within


def in_plane(field_t: ArrayLike, gradient_t_per_m: ArrayLike) -> np.ndarray:
    """(Bx, By, Gxx, Gxy, Gyy) of a field (≥ 2,) and of the in-plane gradient, given as its three
    components (Gxx, Gxy, Gyy) or as the tensor (3, 3)."""
    gradient = np.asarray(gradient_t_per_m, float)
    if gradient.shape == (3, 3):
        gradient = np.array([gradient[0, 0], gradient[0, 1], gradient[1, 1]])
    return np.r_[np.asarray(field_t, float)[:2], gradient]


def in_plane_std(field_covariance_t2: ArrayLike, gradient_covariance: ArrayLike) -> np.ndarray:
    """σ of (Bx, By, Gxx, Gxy, Gyy) from the field's covariance (2, 2) and the gradient's (3, 3),
    either given flat, as a decomposition's message carries them."""
    field = np.reshape(np.asarray(field_covariance_t2, float), (2, 2))
    gradient = np.reshape(np.asarray(gradient_covariance, float), (3, 3))
    return np.sqrt(np.r_[np.diag(field), np.diag(gradient)])


def scene_truth(scenario: Scenario, probe_id: int = 0) -> np.ndarray:
    """(Bx, By, Gxx, Gxy, Gyy) that a rotation sweep of the scene's probe ``probe_id`` determines
    (module docstring)."""
    placed = scenario.placed_probes()[probe_id]
    field, gradient = swept_reference_at(
        scenario.environment.source, placed.pose.magnet_position_m, placed.probe.lever_m
    )
    return in_plane(field, gradient)


@dataclasses.dataclass(frozen=True)
class Component:
    """One component of one probe's decomposition against the truth, SI units."""

    probe_id: int
    quantity: str  # one of QUANTITIES
    value: float
    sigma: float
    truth: float
    pull: float  # (value − truth)/σ


def against_truth(scenario: Scenario, probe_id: int, value: ArrayLike, sigma: ArrayLike) -> list[Component]:
    """The five components ``value`` ± ``sigma`` (:func:`in_plane`, :func:`in_plane_std`) of the
    scene's probe ``probe_id`` against its truth (:func:`scene_truth`)."""
    truth = scene_truth(scenario, probe_id)
    values, sigmas = np.asarray(value, float), np.asarray(sigma, float)
    return [
        Component(probe_id, name, float(v), float(s), float(t), float((v - t) / s))
        for name, v, s, t in zip(QUANTITIES, values, sigmas, truth)
    ]


@dataclasses.dataclass(frozen=True)
class Pulls:
    """The pulls of some components: how many, how many within ``WITHIN_SIGMAS``, the largest
    |pull| and the mean pull² (1 for a calibrated σ)."""

    count: int
    within: int
    largest: float
    mean_square: float

    @classmethod
    def of(cls, components: list[Component]) -> Pulls:
        pulls = np.array([c.pull for c in components], float)
        if not pulls.size:
            return cls(0, 0, float("nan"), float("nan"))
        within = int(np.sum(np.abs(pulls) <= WITHIN_SIGMAS))
        return cls(pulls.size, within, float(np.max(np.abs(pulls))), float(np.mean(pulls**2)))

    def report(self) -> str:
        return (
            f"{self.within} of {self.count} components within {WITHIN_SIGMAS:g}σ, the largest pull "
            f"{self.largest:.2f}σ, mean pull² {self.mean_square:.2f} (1 for a calibrated σ)"
        )
