"""The least-squares problem of a ring-down fit of K ≥ 1 tones in one window, solved by variable
projection, and its Fisher information (docs/physics.md §11): what
:func:`mows.estimate.ringdown.fit_ringdowns` iterates on and what the Cramér–Rao bound is
computed from. The model and its derivatives are the compiled kernels of
:mod:`mows.estimate.ringdown.model`.

q holds each tone's nonlinear parameters in turn, (f, δ, θmax, φ[, ε]) per tone; the linear
ones of each channel are (κ_1 … κ_K, B_DC).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.estimate.ringdown.model import evaluate_model, levenberg_marquardt, split_pickup
from mows.estimate.ringdown.types import FitOptions, ProbeLine
from mows.physics.schema import Vector

NONLINEAR = ("frequency_hz", "damping_per_s", "amplitude_rad", "phase_rad")


@dataclasses.dataclass(frozen=True)
class RingdownProblem:
    """Data and fixed settings of one fit: y is (C, n), uniformly sampled every ``dt``;
    ``pickups`` (K, L) the C_k of each tone's g (complex) at its commanded θ0, zero-padded."""

    y: np.ndarray
    weights: np.ndarray  # 1/σ per channel
    dt: float  # sample interval, s (t = 0 at the first sample)
    pickups: np.ndarray
    offset_free: bool  # each tone's last parameter ε turns its pickup, g(ε + x): the rest offset (or θ0's error)

    @property
    def tones(self) -> int:
        return int(self.pickups.shape[0])

    @property
    def per_tone(self) -> int:
        """Nonlinear parameters per tone: f, δ, θmax, φ and ε where it is free."""
        return len(NONLINEAR) + int(self.offset_free)

    def kernel_data(self) -> tuple[float, np.ndarray, np.ndarray, bool, np.ndarray, np.ndarray]:
        """The data and settings as the compiled kernels take them: (dt, Re C_k, Im C_k, offset
        free, y, weights)."""
        cr, ci = split_pickup(self.pickups)
        return self.dt, cr, ci, self.offset_free, self.y, self.weights

    def fitted_pickup(self, q: NDArray[np.float64], tone: int = 0) -> NDArray[np.complex128]:
        """The C_k of ``tone``'s model at q: turned by its ε when it is free, g(ε + x), as
        :func:`mows.estimate.ringdown.model.evaluate_model` turns them."""
        pickup = self.pickups[tone]
        if not self.offset_free:
            return pickup
        return pickup * np.exp(1j * np.arange(pickup.size) * q[(tone + 1) * self.per_tone - 1])

    def subsampled(self, step: int) -> RingdownProblem:
        return dataclasses.replace(self, y=np.ascontiguousarray(self.y[:, ::step]), dt=self.dt * step)


def padded_pickups(pickups: Sequence[ArrayLike]) -> NDArray[np.complex128]:
    """The tones' pickup series as one (K, L) array, each zero-padded to the longest."""
    series = [np.asarray(p, complex).ravel() for p in pickups]
    out = np.zeros((len(series), max(s.size for s in series)), complex)
    for k, s in enumerate(series):
        out[k, : s.size] = s
    return out


@dataclasses.dataclass
class Evaluation:
    """Everything known at one parameter vector q: each tone's shape g (K, n) and ∂g/∂q
    (``dg``, (K·P, n)), κ of each tone and B_DC per channel (``coef``, (C, K + 1)) and the
    weighted cost."""

    q: np.ndarray
    g: np.ndarray
    dg: np.ndarray
    coef: np.ndarray
    residual: np.ndarray  # (C, n), unweighted
    cost: float  # Σ_c (w_c·|r_c|)²
    # The projected normal matrix of q (κ and B_DC eliminated) at q, weighted by w_c²: its
    # inverse is q's covariance at the noise level 1/w. None where it was not formed.
    normal_matrix: np.ndarray | None = None


def finite_cost(cost: float) -> float:
    """A cost that compares: +∞ for one that is not finite (a diverged evaluation)."""
    return cost if math.isfinite(cost) else math.inf


def evaluate(problem: RingdownProblem, q: NDArray[np.float64], derivatives: bool = True) -> Evaluation:
    """Variable projection at q (Golub–Pereyra, with Kaufman's Jacobian): κ and B_DC by linear
    least squares, the residual and the projected normal equations of q
    (:func:`mows.estimate.ringdown.model.normal_equations`, where the numerics are explained)."""
    n_ch, n = problem.y.shape
    p, n_tones = q.size, problem.tones
    g, m = np.empty((n_tones, n)), np.empty((p if derivatives else 0, n))
    residual, coef = np.empty((n_ch, n)), np.empty((n_ch, n_tones + 1))
    jtj, jtr = np.zeros((p, p)), np.zeros(p)
    cost = evaluate_model(np.asarray(q, float), *problem.kernel_data(), derivatives, g, m, residual, coef, jtj, jtr)
    return Evaluation(q, g, m, coef, residual, float(cost), jtj if derivatives else None)


def _column_scale(jtj: NDArray[np.float64]) -> NDArray[np.float64]:
    """Parameters differ by ~1e20 in scale (Hz against tesla); equilibrate before solving."""
    scale = np.sqrt(np.diag(jtj))
    scale[scale == 0] = 1.0
    return scale


def scaled_inverse(jtj: NDArray[np.float64]) -> NDArray[np.float64]:
    """(JᵀJ)⁻¹ computed on the equilibrated matrix; raises LinAlgError if singular."""
    scale = _column_scale(jtj)
    return np.linalg.inv(jtj / np.outer(scale, scale)) / np.outer(scale, scale)


def fisher_information(step: Evaluation, weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Fisher information (JᵀJ with weights) over all parameters: q, then (κ_1 … κ_K, B_DC) of
    each channel. J's columns are κ_c,k·∂g_k/∂q, g_k and 1, so JᵀJ is assembled from Gram sums
    of those rows without forming the n × P Jacobian."""
    m, g = step.dg, step.g
    p, n_tones, n_ch = m.shape[0], g.shape[0], step.coef.shape[0]
    per_tone = p // n_tones
    n_lin = n_tones + 1
    gram = np.empty((p + n_lin, p + n_lin))  # the Gram matrix of the rows M, g_1 … g_K, 1
    gram[:p, :p] = m @ m.T
    gram[:p, p:-1] = m @ g.T
    gram[:p, -1] = m.sum(axis=1)
    gram[p:-1, p:-1] = g @ g.T
    gram[p:-1, -1] = g.sum(axis=1)
    gram[-1, -1] = g.shape[1]
    gram[p:, :p] = gram[:p, p:].T
    gram[-1, p:-1] = gram[p:-1, -1]
    fisher = np.zeros((p + n_lin * n_ch, p + n_lin * n_ch))
    for c in range(n_ch):
        scale = np.concatenate([np.repeat(step.coef[c, :n_tones], per_tone), np.ones(n_lin)])
        idx = np.r_[0:p, p + n_lin * c : p + n_lin * (c + 1)]
        fisher[np.ix_(idx, idx)] += weights[c] ** 2 * gram * np.outer(scale, scale)
    return fisher


AMPLITUDE_BOUNDS_RAD = (math.radians(0.5), math.radians(90.0))
AMPLITUDE = NONLINEAR.index("amplitude_rad")


def variable_projection(
    problem: RingdownProblem, q: ArrayLike, iterations: int, tol_chi2: float, damping: float = 1e-3
) -> tuple[Evaluation, bool, int, NDArray[np.bool_]]:
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
    return Evaluation(q, g, m, coef, residual, float(cost), jtj), bool(converged), int(used), free


# --- the bound itself -------------------------------------------------------------------
def cramer_rao_hz(
    n_samples: int,
    sample_rate_hz: float,
    lines: Sequence[ProbeLine],
    truth: Sequence[Sequence[float]],
    noise_std_t: float,
    rest_offsets_rad: Sequence[float] | None = None,
    sensor_direction: Vector = (0.0, 1.0),
) -> NDArray[np.float64]:
    """(K,): the Cramér–Rao bound of each tone's frequency in the presence of the others, for
    one channel of ``n_samples`` in white noise σ: √[(JᵀJ/σ²)⁻¹]_{f_k f_k} (docs/physics.md
    §11), J the Jacobian of the full model over all its parameters at the given values.
    ``truth[k]`` = (f, δ, θmax, φ, κ) of tone k, whose pickup is ``lines[k]``'s
    (:meth:`ProbeLine.pickup_series`); ``rest_offsets_rad`` the ε of each where the fit frees it
    (``FitOptions.rest_offset_free``, or θ0's error with ``theta0_free``), None where it does
    not. t = 0 at the first sample."""
    offsets = None if rest_offsets_rad is None else [float(e) for e in rest_offsets_rad]
    q = np.concatenate(
        [list(row[:4]) + ([] if offsets is None else [offsets[k]]) for k, row in enumerate(truth)]
    ).astype(float)
    problem = RingdownProblem(
        np.zeros((1, int(n_samples))),
        np.array([1.0 / noise_std_t]),
        1.0 / sample_rate_hz,
        padded_pickups([line.pickup_series(FitOptions(sensor_direction=tuple(sensor_direction))) for line in lines]),
        offsets is not None,
    )
    step = evaluate(problem, q)
    step.coef = np.array([[row[4] for row in truth] + [0.0]])
    inverse = scaled_inverse(fisher_information(step, problem.weights))
    return np.sqrt(np.diag(inverse)[0 : q.size : problem.per_tone])


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
    """:func:`cramer_rao_hz` of one tone: the bound of f over (f, δ, θmax, φ, [ε], κ, B_DC) at
    the given values, ε the rest offset (or θ0's error) where ``offset_free`` (as the fit had
    it); ``pickup`` the series at the commanded θ0 (None: the paper's single term for a sensor
    along ``sensor_direction``)."""
    line = ProbeLine(0, theta0_rad, frequency_hz, None if pickup is None else tuple(np.asarray(pickup, complex)))
    truth = [(frequency_hz, damping_per_s, amplitude_rad, phase_rad, kappa_t)]
    offsets = [rest_offset_rad] if offset_free else None
    return float(cramer_rao_hz(n_samples, sample_rate_hz, [line], truth, noise_std_t, offsets, sensor_direction)[0])
