"""The 3D scene's arrows: each probe's in-plane field B and its gradient's principal directions,
labelled value ± σ. The B arrows' lengths are scaled so that the largest |B| is
``arrow_length_m``; a principal gradient's length is its significance |λ|/σ_λ, full length
(``arrow_length_m``) from ``FULL_SIGNIFICANCE`` σ up, so a gradient the data do not separate from
zero is drawn short rather than as large as a measured one (and not at all where σ_λ is unknown).

B = (Bx, By) in the sweep's rotation-plane frame (x = e1, y = e2, docs/architecture.md "Frames
and geometry"); |B| ± σ with σ² = uᵀΣu, u = B/|B| (first order). The in-plane gradient
[[Gxx, Gxy], [Gxy, Gyy]] (G_ij = ∂B_i/∂x_j, symmetric in free space) has eigenvalues λ along
orthogonal directions v; to first order dλ = vᵀ dG v, so σ_λ² = aᵀΣa with
a = (v_x², 2·v_x·v_y, v_y²) over (Gxx, Gxy, Gyy). A negative λ is drawn pointing inwards: two
arrows from the probe's place outwards for λ > 0 (the field grows along ±v), towards it for
λ < 0. The field along the probe axis of one ring-down (``/mows/field``, Eq. 6 assuming G = 0)
is one arrow along x' of the probe frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

ARROW_LENGTH_M = 0.05  # the largest B arrow, and a principal gradient of FULL_SIGNIFICANCE σ or more
FULL_SIGNIFICANCE = 5.0  # |λ|/σ_λ drawn at full length


@dataclass(frozen=True)
class Arrow:
    """One arrow of the scene: from ``tail_m`` along the unit ``direction`` in ``frame_id``."""

    frame_id: str
    tail_m: NDArray[np.float64]
    direction: NDArray[np.float64]
    length_m: float
    kind: str  # "B" (field), "G" (a principal gradient), "B∥" (along the probe axis), "pose" (a sweep's)
    label: str  # value ± σ; "" on the second arrow of a principal direction


@dataclass(frozen=True)
class Principal:
    """A principal value of the in-plane gradient (T/m), its σ and its unit direction (x, y)."""

    value_t_per_m: float
    std_t_per_m: float
    direction: NDArray[np.float64]


@dataclass(frozen=True)
class ProbeField:
    """What the scene shows of one probe: where (``position_m`` in ``frame_id``), its in-plane B
    (T) and gradient (Gxx, Gxy, Gyy, T/m) with their covariances (row-major 2x2, 3x3)."""

    probe_id: int
    frame_id: str
    position_m: NDArray[np.float64]
    field_t: NDArray[np.float64]
    field_covariance_t2: NDArray[np.float64]
    gradient_t_per_m: NDArray[np.float64]
    gradient_covariance: NDArray[np.float64]

    @classmethod
    def of(cls, msg, frame_id: str, position_m: ArrayLike = (0.0, 0.0, 0.0)) -> ProbeField:
        """From a SweepDecomposition or a FieldMap's ProbeField message."""
        return cls(
            int(msg.probe_id),
            frame_id,
            np.asarray(position_m, float),
            np.asarray(msg.field_t, float),
            np.asarray(msg.field_covariance_t2, float).reshape(2, 2),
            np.asarray(msg.gradient_t_per_m, float),
            np.asarray(msg.gradient_covariance, float).reshape(3, 3),
        )

    @property
    def known(self) -> bool:
        return bool(np.all(np.isfinite(self.field_t)) and np.all(np.isfinite(self.gradient_t_per_m)))


def field_magnitude(field_t: ArrayLike, covariance_t2: ArrayLike) -> tuple[float, float]:
    """|B| and its σ (module docstring), tesla."""
    field = np.asarray(field_t, float)
    magnitude = float(np.hypot(*field))
    if magnitude == 0.0:
        return 0.0, float(math.sqrt(max(np.trace(np.asarray(covariance_t2, float)) / 2, 0.0)))
    u = field / magnitude
    return magnitude, float(math.sqrt(max(u @ np.asarray(covariance_t2, float) @ u, 0.0)))


def principal_gradients(gradient_t_per_m: ArrayLike, covariance: ArrayLike) -> list[Principal]:
    """The in-plane gradient's eigenvalues with their σ and directions, largest |λ| first."""
    gxx, gxy, gyy = np.asarray(gradient_t_per_m, float)
    values, vectors = np.linalg.eigh(np.array([[gxx, gxy], [gxy, gyy]]))
    sigma = np.asarray(covariance, float).reshape(3, 3)
    principals = []
    for value, v in zip(values, vectors.T):
        a = np.array([v[0] ** 2, 2 * v[0] * v[1], v[1] ** 2])
        principals.append(Principal(float(value), float(math.sqrt(max(a @ sigma @ a, 0.0))), v))
    return sorted(principals, key=lambda p: -abs(p.value_t_per_m))


def probe_arrows(probes: list[ProbeField], arrow_length_m: float = ARROW_LENGTH_M) -> dict[int, list[Arrow]]:
    """Each known probe's arrows: B, then the gradient's two principal directions (each drawn
    both ways, module docstring); the largest |B| of all probes is ``arrow_length_m`` long, a
    principal gradient :func:`significance_length_m` long."""
    known = [p for p in probes if p.known]
    fields = {p.probe_id: field_magnitude(p.field_t, p.field_covariance_t2) for p in known}
    principals = {p.probe_id: principal_gradients(p.gradient_t_per_m, p.gradient_covariance) for p in known}
    largest_b = max((b for b, _ in fields.values()), default=0.0) or 1.0
    arrows: dict[int, list[Arrow]] = {}
    for probe in known:
        b, b_std = fields[probe.probe_id]
        direction = np.append(probe.field_t / b, 0.0) if b > 0 else np.array([1.0, 0.0, 0.0])
        shown = [
            Arrow(
                probe.frame_id,
                probe.position_m,
                direction,
                arrow_length_m * b / largest_b,
                "B",
                f"B {_tesla(b, b_std)}",
            )
        ]
        for index, q in enumerate(principals[probe.probe_id], start=1):
            length = significance_length_m(q, arrow_length_m)
            label = f"G{index} {q.value_t_per_m * 1e3:+.3g} ± {q.std_t_per_m * 1e3:.2g} mT/m"
            for sign in (1.0, -1.0):
                along = sign * np.append(q.direction, 0.0)
                # λ < 0: the arrow ends at the probe's place, pointing in.
                tail = probe.position_m + (along * length if q.value_t_per_m < 0 else 0.0)
                shown.append(
                    Arrow(
                        probe.frame_id,
                        tail,
                        along if q.value_t_per_m >= 0 else -along,
                        length,
                        "G",
                        label if sign > 0 else "",
                    )
                )
        arrows[probe.probe_id] = shown
    return arrows


def significance_length_m(principal: Principal, arrow_length_m: float = ARROW_LENGTH_M) -> float:
    """A principal gradient's arrow length: ``arrow_length_m`` times its significance |λ|/σ_λ
    over :data:`FULL_SIGNIFICANCE`, at most ``arrow_length_m``; zero where σ_λ is not known."""
    value, std = abs(principal.value_t_per_m), principal.std_t_per_m
    if not math.isfinite(std) or not math.isfinite(value):
        return 0.0
    significance = value / std if std > 0 else (math.inf if value > 0 else 0.0)
    return arrow_length_m * min(significance, FULL_SIGNIFICANCE) / FULL_SIGNIFICANCE


def axis_arrow(frame_id: str, field_along_axis_t: float, std_t: float, arrow_length_m: float = ARROW_LENGTH_M) -> Arrow:
    """The field along the probe axis x' of one ring-down (signed: a negative field points
    along −x'), ``arrow_length_m`` long, labelled with its value ± σ."""
    sign = -1.0 if field_along_axis_t < 0 else 1.0
    return Arrow(
        frame_id,
        np.zeros(3),
        np.array([sign, 0.0, 0.0]),
        arrow_length_m,
        "B∥",
        f"B∥ {_tesla(field_along_axis_t, std_t)}",
    )


def _tesla(value_t: float, std_t: float) -> str:
    return f"{value_t * 1e6:.4g} ± {std_t * 1e6:.2g} µT"
