"""Five more tables whose truth holds physics the catalog lacks, each acting in another channel of
the potential (tests/lab/outside_catalog.py registers them beside its own five).

Built as those are (the independent truth of tests/lab/independent_truth.py, rotation sweeps in
15° steps, σf = 0.33 mHz), from mechanisms real MOWS probes, stages and benches have:

=========================  =============================================  ========================
case                       hidden term                                    channel × monomial
=========================  =============================================  ========================
``moment_coil_heating``    the coil's heat warms the magnet: m·(1 + c·I²)  moment × I²
``coil_axis_field``        the coil's field has a y part the reference     field_y × I
                           misses (its axis 0.6 % off)
``stray_field_temperature`` a stage magnet's field (in the reference at     field_x × (T − T_ref)
                           T_ref) falls with temperature
``mount_rotation``         the mount turns with temperature:               angle × (T − T_ref)
                           θ0 + a·(T − T_ref) (the angle output)
``magnet_off_lever``       the magnet glued δ beyond its place on the      magnet_along × 1
                           lever, in a gradient (the magnet position output)
=========================  =============================================  ========================

The temperatures of the last three run symmetrically about the probe's reference temperature, so
that the hidden term has no mean (a mean would be a catalog field or angle offset).
"""

from __future__ import annotations

import math

import numpy as np

from lab.independent_truth import Rows, Scene
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE
from mows.physics.sources import LinearGradient

NOISE_HZ = 3.3e-4
REFERENCE_K = 293.15
EARTH_T = np.array([15e-6, -12e-6, -40e-6])
DESIGN_SEED = 20_240_612
SMALL_SWING_RAD = math.radians(2.0)
COIL_T_PER_A = 2.52e-4  # a Helmholtz pair at its centre (tests/lab/outside_catalog.py's)
CURRENTS_A = (-2.0, -1.0, 0.0, 1.0, 2.0)
MOMENT_PER_A2 = -1e-3  # the magnet warms ~1 K/A² (NdFeB −1e-3/K)
AXIS_T_PER_A = 1.5e-6  # the coil's field 0.6 % along y
BIAS_T = (0.0, 3e-4, 0.0)  # a second, constant field across the coil's axis (in the reference)
STRAY_T = 2e-4  # a stage motor's magnet, along x at the probe, measured at T_ref
STRAY_PER_K = -1.2e-3  # NdFeB remanence
MAIN_FIELD_T = (0.0, 4.3e-4, -4e-5)
ROTATION_PER_K = 1e-3  # rad/K: a printed mount
ROTATION_FIELD_T = (4.0e-4, 1.5e-4, -4e-5)
GRADIENT_T_PER_M = 3e-2
GRADIENT_FIELD_T = (2e-4, 1e-4, 0.0)
MAGNET_ALONG_M = 3e-5


def _uniform(field_t, n: int) -> Scene:
    return Scene.uniform(np.broadcast_to(np.asarray(field_t, float), (n, 3)))


def _latin_currents_a(sweeps: int, angles: int) -> np.ndarray:
    rng = np.random.default_rng(DESIGN_SEED)
    per_angle = np.stack([rng.permutation(np.asarray(CURRENTS_A)) for _ in range(angles)], axis=1)
    return per_angle[:sweeps].reshape(-1)


def symmetric_temperatures_k(t_s: np.ndarray) -> np.ndarray:
    """A warming by 10 K through the reference temperature, with ±2 K of scatter."""
    scatter = np.random.default_rng(DESIGN_SEED + 1).uniform(-2.0, 2.0, len(t_s))
    return REFERENCE_K + 10.0 * (t_s / np.ptp(t_s) - 0.5) + scatter


def moment_coil_heating(sweeps, hidden: bool):
    """Five sweeps in a coil along x, −2…2 A in a Latin square (0.25 mT/A), and the Earth's field;
    the coil's heat lowers the moment by 1e-3/A²: β0·c·B∥·I², ±7 mHz at ±2 A (the frequency sees
    a term of degree 3, I³·cos θ0; the moment, one of degree 2)."""
    theta0, columns = sweeps(len(CURRENTS_A))
    current = _latin_currents_a(len(CURRENTS_A), len(theta0) // len(CURRENTS_A))
    columns["coil_current_a"] = current
    scene = Scene.of([UniformField((COIL_T_PER_A, 0.0, 0.0))], [current]) + _uniform(EARTH_T, len(theta0))
    scale = MOMENT_PER_A2 * current**2 if hidden else 0.0
    return columns, Rows.of(PAPER_PROBE, theta0, scene, moment_scale=scale), np.full(len(theta0), SMALL_SWING_RAD)


def coil_axis_field(sweeps, hidden: bool):
    """The coil of :func:`moment_coil_heating` beside a constant 0.3 mT along y, and the coil's
    field has 1.5 µT/A along y that the reference (the coil along x) misses: ±11 mHz at ±2 A. An
    angle offset would turn the constant field too, so the catalog has no stand-in."""
    theta0, columns = sweeps(len(CURRENTS_A))
    current = _latin_currents_a(len(CURRENTS_A), len(theta0) // len(CURRENTS_A))
    columns["coil_current_a"] = current
    seen = Scene.of([UniformField((COIL_T_PER_A, 0.0, 0.0))], [current]) + _uniform(
        np.add(BIAS_T, EARTH_T), len(theta0)
    )
    missed = Scene.of([UniformField((0.0, AXIS_T_PER_A if hidden else 0.0, 0.0))], [current])
    field, _ = seen.reference()
    columns.update(ref_bx_t=field[:, 0], ref_by_t=field[:, 1], ref_bz_t=field[:, 2])
    return columns, Rows.of(PAPER_PROBE, theta0, seen + missed), np.full(len(theta0), SMALL_SWING_RAD)


def stray_field_temperature(sweeps, hidden: bool):
    """Four sweeps in 0.43 mT along y beside a stage magnet's 0.2 mT along x, which the reference
    holds as measured at T_ref; the magnet's field falls by 1.2e-3/K while the probe warms through
    T_ref: ±1.2 µT, ±4.4 mHz at the ends."""
    theta0, columns = sweeps(4)
    columns["temperature_k"] = symmetric_temperatures_k(columns["t_s"])
    change = STRAY_PER_K * (columns["temperature_k"] - REFERENCE_K) if hidden else np.zeros(len(theta0))
    seen = _uniform(np.add(MAIN_FIELD_T, (STRAY_T, 0.0, 0.0)), len(theta0))
    field, _ = seen.reference()
    columns.update(ref_bx_t=field[:, 0], ref_by_t=field[:, 1], ref_bz_t=field[:, 2])
    missed = Scene.of([UniformField((STRAY_T, 0.0, 0.0))], [change])
    # 1° swings: at 2° the finite amplitude's harmonic 1 (0.19 mHz in this field) sits just below
    # the evidence the selection asks for (ΔBIC 9.2), and its control would keep that structure.
    return columns, Rows.of(PAPER_PROBE, theta0, seen + missed), np.full(len(theta0), SMALL_SWING_RAD / 2.0)


def mount_rotation(sweeps, hidden: bool):
    """Four sweeps in 0.43 mT while the probe warms through T_ref and its mount turns by
    1e-3 rad/K (±0.29° at the ends; the table's θ0 is the stage's): ±8 mHz at the ends."""
    theta0, columns = sweeps(4)
    columns["temperature_k"] = symmetric_temperatures_k(columns["t_s"])
    columns["theta0_deg"] = np.degrees(theta0)
    turned = theta0 + (ROTATION_PER_K * (columns["temperature_k"] - REFERENCE_K) if hidden else 0.0)
    rows = Rows.of(PAPER_PROBE, turned, _uniform(ROTATION_FIELD_T, len(theta0)))
    return columns, rows, np.full(len(theta0), SMALL_SWING_RAD)


def magnet_off_lever(sweeps, hidden: bool):
    """Four sweeps in 0.22 mT and a 30 mT/m gradient (Gxx = −Gyy) whose sign alternates by sweep;
    the magnet sits 30 µm beyond its place on the 1.9 mm lever: ≈ 2·m·δ·Gx'x' in the spring,
    ±8 mHz as cos 2θ0 that flips with the gradient (a free deflection's harmonic 2 does not)."""
    theta0, columns = sweeps(4)
    sign = np.where(columns["sweep"] % 2 == 0, 1.0, -1.0)
    gradient = LinearGradient(np.diag([GRADIENT_T_PER_M, -GRADIENT_T_PER_M, 0.0]))
    scene = Scene.of([gradient], [sign]) + _uniform(GRADIENT_FIELD_T, len(theta0))
    rows = Rows.of(PAPER_PROBE, theta0, scene)
    if hidden:
        rows = Rows(
            rows.probe, rows.theta0_rad, scene, rows.moment_am2, rows.spring_nm_per_rad, magnet_along_m=MAGNET_ALONG_M
        )
    return columns, rows, np.full(len(theta0), SMALL_SWING_RAD)


PLUGINS = {
    "moment_coil_heating": (
        "moment_coil_heating",
        {"c_per_a2": MOMENT_PER_A2},
        '''"""The coil's heat warms the magnet: m(I) = m·(1 + c·I²)."""
from mows.lab import effect


@effect(name="moment_coil_heating", parameters={"c_per_a2": (0.0, -1e-1, 1e-1, "1/A²")})
def moment_coil_heating(rows, c_per_a2):
    return {"moment_scale": c_per_a2 * rows.coil_current_a**2}
''',
    ),
    "coil_axis_field": (
        "coil_axis_field",
        {"by_t_per_a": AXIS_T_PER_A},
        '''"""The coil's field has a part along y that the reference misses, ∝ I."""
import numpy as np

from mows.lab import effect


@effect(name="coil_axis_field", parameters={"by_t_per_a": (0.0, -1e-4, 1e-4, "T/A")})
def coil_axis_field(rows, by_t_per_a):
    return {"field_offset_t": np.multiply.outer(by_t_per_a * rows.coil_current_a, (0.0, 1.0))}
''',
    ),
    "stray_field_temperature": (
        "stray_field_temperature",
        {"bx_t_per_k": STRAY_T * STRAY_PER_K},
        f'''"""A stage magnet's field at the probe falls with temperature (measured at {REFERENCE_K} K)."""
import numpy as np

from mows.lab import effect


@effect(name="stray_field_temperature", parameters={{"bx_t_per_k": (0.0, -1e-5, 1e-5, "T/K")}})
def stray_field_temperature(rows, bx_t_per_k):
    return {{"field_offset_t": np.multiply.outer(bx_t_per_k * (rows.temperature_k - {REFERENCE_K}), (1.0, 0.0))}}
''',
    ),
    "mount_rotation": (
        "mount_rotation",
        {"rad_per_k": ROTATION_PER_K},
        f'''"""The probe's mount turns with temperature."""
from mows.lab import effect


@effect(name="mount_rotation", parameters={{"rad_per_k": (0.0, -1e-1, 1e-1, "rad/K")}})
def mount_rotation(rows, rad_per_k):
    return {{"angle_offset_rad": rad_per_k * (rows.temperature_k - {REFERENCE_K})}}
''',
    ),
    "magnet_off_lever": (
        "magnet_off_lever",
        {"along_m": MAGNET_ALONG_M},
        '''"""The magnet sits beyond its nominal place along the lever."""
from mows.lab import effect


@effect(name="magnet_off_lever", parameters={"along_m": (0.0, -1e-3, 1e-3, "m")})
def magnet_off_lever(rows, along_m):
    return {"magnet_offset_m": (along_m, 0.0)}
''',
    ),
}
FAMILIES = {
    "moment_coil_heating": "moment_current_squared",
    "coil_axis_field": "field_y_current",
    "stray_field_temperature": "field_x_temperature",
    "mount_rotation": "angle_temperature",
    "magnet_off_lever": "magnet_along",
}
DESIGNS = {
    "moment_coil_heating": moment_coil_heating,
    "coil_axis_field": coil_axis_field,
    "stray_field_temperature": stray_field_temperature,
    "mount_rotation": mount_rotation,
    "magnet_off_lever": magnet_off_lever,
}
