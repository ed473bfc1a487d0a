"""The least-squares problem of one ring-down fit, solved by variable projection, and its
Fisher information (docs/physics.md §11): what :func:`mows.estimate.ringdown.fit_ringdown` iterates
on and what the Cramér–Rao bound is computed from. The model and its derivatives are the
compiled kernels of :mod:`mows.estimate.ringdown.model`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.estimate.ringdown.model import evaluate_model, levenberg_marquardt, split_pickup
from mows.physics.fluxgate import paper_pickup
from mows.physics.schema import Vector

NONLINEAR = ("frequency_hz", "damping_per_s", "amplitude_rad", "phase_rad")


@dataclasses.dataclass
class Shape:
    """g(x(t)) and dg/dq at the samples (:mod:`mows.estimate.ringdown.model`)."""

    g: np.ndarray  # (n,)
    dg_dq: np.ndarray  # (len(q), n)


@dataclasses.dataclass(frozen=True)
class RingdownProblem:
    """Data and fixed settings of one fit: y is (C, n), uniformly sampled every ``dt``."""

    y: np.ndarray
    weights: np.ndarray  # 1/σ per channel
    dt: float  # sample interval, s (t = 0 at the first sample)
    theta0: float
    pickup: np.ndarray  # C_k of g (complex) at the commanded θ0
    offset_free: bool  # q[4] = ε turns the pickup, g(ε + x): the rest offset (or θ0's error)

    def kernel_data(self) -> tuple[float, np.ndarray, np.ndarray, bool, np.ndarray, np.ndarray]:
        """The data and settings as the compiled kernels take them: (dt, Re C_k, Im C_k, offset
        free, y, weights)."""
        cr, ci = split_pickup(self.pickup)
        return self.dt, cr, ci, self.offset_free, self.y, self.weights

    def fitted_pickup(self, q: NDArray[np.float64]) -> NDArray[np.complex128]:
        """The C_k of the model at q: turned by ε = q[4] when it is free, g(ε + x), as
        :func:`mows.estimate.ringdown.model.evaluate_model` turns them."""
        if not self.offset_free:
            return self.pickup
        return self.pickup * np.exp(1j * np.arange(self.pickup.size) * q[4])

    def subsampled(self, step: int) -> RingdownProblem:
        return dataclasses.replace(self, y=np.ascontiguousarray(self.y[:, ::step]), dt=self.dt * step)


@dataclasses.dataclass
class Step:
    """Everything known at one parameter vector q: the shape, κ and B_DC per channel
    (``coef``, (C, 2)) and the weighted cost."""

    q: np.ndarray
    shape: Shape
    coef: np.ndarray
    residual: np.ndarray  # (C, n), unweighted
    cost: float  # Σ_c (w_c·|r_c|)²
    # The projected normal matrix of q (κ and B_DC eliminated) at q, weighted by w_c²: its
    # inverse is q's covariance at the noise level 1/w. None where it was not formed.
    normal_matrix: np.ndarray | None = None


def evaluate(problem: RingdownProblem, q: NDArray[np.float64], derivatives: bool = True) -> Step:
    """Variable projection at q (Golub–Pereyra, with Kaufman's Jacobian): κ and B_DC by linear
    least squares, the residual and the projected normal equations of q
    (:func:`mows.estimate.ringdown.model.normal_equations`, where the numerics are explained)."""
    n_ch, n = problem.y.shape
    p = q.size
    g, m = np.empty(n), np.empty((p if derivatives else 0, n))
    residual, coef = np.empty((n_ch, n)), np.empty((n_ch, 2))
    jtj, jtr = np.zeros((p, p)), np.zeros(p)
    cost = evaluate_model(np.asarray(q, float), *problem.kernel_data(), derivatives, g, m, residual, coef, jtj, jtr)
    return Step(q, Shape(g, m), coef, residual, float(cost), jtj if derivatives else None)


def _column_scale(jtj: NDArray[np.float64]) -> NDArray[np.float64]:
    """Parameters differ by ~1e20 in scale (Hz against tesla); equilibrate before solving."""
    scale = np.sqrt(np.diag(jtj))
    scale[scale == 0] = 1.0
    return scale


def scaled_inverse(jtj: NDArray[np.float64]) -> NDArray[np.float64]:
    """(JᵀJ)⁻¹ computed on the equilibrated matrix; raises LinAlgError if singular."""
    scale = _column_scale(jtj)
    return np.linalg.inv(jtj / np.outer(scale, scale)) / np.outer(scale, scale)


def fisher_information(step: Step, weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Fisher information (JᵀJ with weights) over all parameters: q, then κ and B_DC of each
    channel. J's columns are κ_c·∂g/∂q, g and 1, so JᵀJ is assembled from Gram sums of
    those rows without forming the n × P Jacobian."""
    m, g = step.shape.dg_dq, step.shape.g
    p, n_ch = m.shape[0], step.coef.shape[0]
    gram = np.empty((p + 2, p + 2))  # Gram matrix of the rows M, g, 1
    gram[:p, :p] = m @ m.T
    gram[:p, p] = gram[p, :p] = m @ g
    gram[:p, p + 1] = gram[p + 1, :p] = m.sum(axis=1)
    gram[p, p], gram[p, p + 1] = g @ g, g.sum()
    gram[p + 1, p], gram[p + 1, p + 1] = gram[p, p + 1], g.size
    fisher = np.zeros((p + 2 * n_ch, p + 2 * n_ch))
    for c in range(n_ch):
        scale = np.concatenate([np.full(p, step.coef[c, 0]), [1.0, 1.0]])
        idx = np.r_[0:p, p + 2 * c, p + 2 * c + 1]
        fisher[np.ix_(idx, idx)] += weights[c] ** 2 * gram * np.outer(scale, scale)
    return fisher


AMPLITUDE_BOUNDS_RAD = (math.radians(0.5), math.radians(90.0))
AMPLITUDE = NONLINEAR.index("amplitude_rad")


def variable_projection(
    problem: RingdownProblem, q: ArrayLike, iterations: int, tol_chi2: float, damping: float = 1e-3
) -> tuple[Step, bool, int, NDArray[np.bool_]]:
    """Levenberg–Marquardt on the nonlinear parameters with κ and B_DC solved exactly at every
    step (Golub–Pereyra variable projection). Eliminating the linear parameters removes the
    curved θmax–κ valley (only κ·θmax is well determined at θ0 = 0°, κ·θmax² at 90°), in
    which a joint fit crawls. Converged when the Gauss–Newton step would lower χ² by less
    than ``tol_chi2``: then f is within √tol_chi2 standard errors of the optimum.

    θmax is kept in ``AMPLITUDE_BOUNDS_RAD`` without changing sign (θmax → −θmax with
    φ → φ + π is the same ring-down, but the path through 0 is singular). Near θ0 = 90° with κ
    free, the only handle on θmax is the x⁴ term of cos x, a fraction θmax²/12 of the signal;
    at low SNR the optimum can run to θmax → 0 with κ → ∞. There θmax is held at its bound (an
    active set) and f, which does not depend on it, converges as usual.

    ``damping`` is the initial Marquardt λ: small when q is already near the optimum. The loop
    is compiled (:func:`mows.estimate.ringdown.model.levenberg_marquardt`): in Python its bookkeeping
    cost more than the model evaluations.

    Returns (the step at the last accepted q, converged, iterations, free-parameter mask).
    """
    q, converged, used, free, cost, g, m, residual, coef, jtj, _ = levenberg_marquardt(
        np.asarray(q, float).copy(),
        *problem.kernel_data(),
        iterations,
        tol_chi2,
        damping,
        *AMPLITUDE_BOUNDS_RAD,
        AMPLITUDE,
    )
    return Step(q, Shape(g, m), coef, residual, float(cost), jtj), bool(converged), int(used), free


# --- the bound itself -------------------------------------------------------------------
def cramer_rao_frequency_hz(
    n_samples: int,
    sample_rate_hz: float,
    frequency_hz: float,
    damping_per_s: float,
    amplitude_rad: float,
    phase_rad: float,
    theta0_rad: float,
    kappa_t: float,
    noise_std_t: float,
    sensor_direction: Vector = (0.0, 1.0),
    offset_free: bool = True,
    pickup: ArrayLike | None = None,
    rest_offset_rad: float = 0.0,
) -> float:
    """Cramér–Rao bound of f for one channel of ``n_samples`` in white noise σ:
    √[(JᵀJ/σ²)⁻¹]_ff (docs/physics.md §11), J the Jacobian of the full model over all its
    parameters (f, δ, θmax, φ, [ε], κ, B_DC) at the given values, ε the rest offset (or θ0's
    error) that ``FitOptions.rest_offset_free`` (``theta0_free``) fits: ``offset_free`` as the
    fit had it. t = 0 at the first sample; ``pickup`` is the series at the commanded θ0.
    """
    q = np.array([frequency_hz, damping_per_s, amplitude_rad, phase_rad] + ([rest_offset_rad] if offset_free else []))
    coefficients = paper_pickup(theta0_rad, sensor_direction) if pickup is None else np.asarray(pickup, complex)
    problem = RingdownProblem(
        np.zeros((1, int(n_samples))),
        np.array([1.0 / noise_std_t]),
        1.0 / sample_rate_hz,
        theta0_rad,
        coefficients,
        offset_free,
    )
    shape = evaluate(problem, q).shape
    step = Step(q, shape, np.array([[kappa_t, 0.0]]), np.empty((1, 0)), math.nan)
    return float(math.sqrt(scaled_inverse(fisher_information(step, problem.weights))[0, 0]))
