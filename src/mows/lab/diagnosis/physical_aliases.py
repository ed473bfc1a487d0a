"""Exact physical aliases: effects that are the same physics on the lever, in words and numbers.

Some effects act identically on a rotation table because the physics makes them so, not by
chance of the angles; the lab states the conversion so that the user sees what one member's
value means as the other:

- **gravity ≡ field_offset**: a plane tilted so that the unit downward vector has the in-plane
  part d pulls the magnet (mass a, lever l) like an unreferenced in-plane field b = (a·g·l/m)·d
  (both enter U(θ) as −vector·u(θ)); a·g·l/m = 154 µT for the paper's probe, so a field offset
  is gravity only if |b| ≤ a·g·l/m.
- **plane_tilt ≡ field_offset** while the reference's Bz is constant: small rotations (t_x, t_y)
  of the plane bring the in-plane field (t_y·Bz, −t_x·Bz).
- **finite_amplitude ≡ moment_scale** while the amplitudes are the same in every row: the
  first-harmonic balance scales the field spring by 2·J1(A)/A (docs/physics.md §6.3), averaged
  over the ring-down's amplitudes, so ε = ⟨2·J1(A)/A⟩ − 1 ≈ −⟨A²⟩/8.
- **thermal_drift ≡ spring_drift** while the temperature changes linearly in time:
  kM·(1 + α·(T − T_ref)) = kM·(1 + r·t) + const with r = α·dT/dt.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import scipy.special

from mows.lab.data.probe_rows import ProbeSet, probe_parts
from mows.lab.data.table import MeasurementTable
from mows.lab.model.configuration import Configuration
from mows.lab.model.factors import base_start_swing_rad, ringdown_nodes
from mows.lab.model.frequency_model import FrequencyModel, table_start_swing_rad
from mows.lab.model.least_squares import FitResult, parameter_values
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2
from mows.physics.probe import Probe

LINEAR_CORRELATION = 0.99  # temperature this correlated with time drifts linearly
CONSTANT_SPREAD = 0.05  # relative spread below which a column counts as constant

FittedValues = dict[str, dict[str, float]]  # effect name → {parameter: fitted value}


def alias_statements(
    names: Iterable[str], fit: FitResult, probes: ProbeSet, fitted: FittedValues | None = None
) -> list[str]:
    """The exact aliases among ``names`` (effect names) in words and numbers. ``fitted`` maps an
    effect name to {parameter: value} where a member's fitted value is known (default: the
    effects of ``fit``'s model)."""
    values = {e.name: parameter_values(fit.effect_parameters(e.name)) for e in fit.model.effects}
    values.update(fitted or {})
    found = []
    for pair, statement in (
        (("gravity", "field_offset"), _gravity_field),
        (("plane_tilt", "field_offset"), _tilt_field),
        (("finite_amplitude", "moment_scale"), _amplitude_scale),
        (("thermal_drift", "spring_drift"), _thermal_spring),
    ):
        if set(pair) <= set(names):
            text = statement(fit.table, probes, values)
            if text:
                found.append(text)
    return found


def gravity_field_t(probe: Probe) -> float:
    """a·g·l/m, T: the in-plane field that acts like gravity with |d| = 1."""
    return probe.magnet_mass_kg * STANDARD_GRAVITY_M_PER_S2 * probe.lever_m / probe.moment_am2


def _gravity_field(table: MeasurementTable, probes: ProbeSet, values: FittedValues) -> str:
    scale = gravity_field_t(probes.first)
    text = (
        f"gravity ≡ field_offset: a plane tilted so that the unit downward vector has the in-plane part d "
        f"acts like an unreferenced field (a·g·l/m)·d, a·g·l/m = {scale * 1e6:.0f} µT"
    )
    if "gravity" in values and values["gravity"]:
        dx, dy = values["gravity"]["down_x"], values["gravity"]["down_y"]
        text += (
            f"; here gravity down = ({dx:.4g}, {dy:.4g}) ≡ field_offset ({scale * dx * 1e6:.3g}, "
            f"{scale * dy * 1e6:.3g}) µT"
        )
    elif "field_offset" in values and values["field_offset"]:
        bx, by = values["field_offset"]["bx_t"], values["field_offset"]["by_t"]
        size = math.hypot(bx, by) / scale
        text += (
            f"; here field_offset ({bx * 1e6:.3g}, {by * 1e6:.3g}) µT ≡ gravity with down = "
            f"({bx / scale:.4g}, {by / scale:.4g})"
        )
        text += (
            f", a tilt of {math.degrees(math.asin(size)):.3g}°"
            if size <= 1
            else f": |d| = {size:.3g} > 1, more than any tilt gives, so not gravity alone"
        )
    return text


def _tilt_field(table: MeasurementTable, probes: ProbeSet, values: FittedValues) -> str:
    if not table.has("ref_bz_t") or _spread(table.ref_bz_t) > CONSTANT_SPREAD:
        return ""
    bz = float(np.mean(table.ref_bz_t))
    text = (
        f"plane_tilt ≡ field_offset while the reference's Bz is constant ({bz * 1e6:.3g} µT): a tilt "
        "(t_x, t_y) brings the in-plane field (t_y·Bz, −t_x·Bz)"
    )
    if "plane_tilt" in values and values["plane_tilt"]:
        tx, ty = values["plane_tilt"]["tilt_x_rad"], values["plane_tilt"]["tilt_y_rad"]
        text += f"; here tilt ({tx:.4g}, {ty:.4g}) rad ≡ field_offset ({ty * bz * 1e6:.3g}, {-tx * bz * 1e6:.3g}) µT"
    return text


def amplitude_scale_error(table: MeasurementTable, probes: ProbeSet) -> tuple[float, float]:
    """(ε, spread) with ε = ⟨2·J1(A)/A⟩ − 1 over the rows' ring-down amplitude nodes (the
    moment scale the finite amplitude looks like), spread its range over the rows."""
    distinct, inverse = FrequencyModel(probes).groups(table)
    scale = np.empty(len(distinct))
    for rows, part, entry in probe_parts(distinct, probes):  # each probe's rows with its constants
        amplitudes, weights = ringdown_nodes(
            Configuration.base(part, entry.probe), base_start_swing_rad(part, entry.probe)
        )
        scale[rows] = (weights * 2.0 * scipy.special.j1(amplitudes) / amplitudes).sum(-1)
    per_row = (scale - 1.0)[inverse]
    return float(np.mean(per_row)), float(np.ptp(per_row))


def _amplitude_scale(table: MeasurementTable, probes: ProbeSet, values: FittedValues) -> str:
    epsilon, spread = amplitude_scale_error(table, probes)
    start = np.degrees(table_start_swing_rad(table, probes))
    text = (
        f"finite_amplitude ≡ moment_scale: the amplitude scales the field spring by ⟨2·J1(A)/A⟩ − 1 ≈ −⟨A²⟩/8 "
        f"= {epsilon * 100:.3g} % over these ring-downs (start {np.median(start):.3g}°)"
    )
    if spread > CONSTANT_SPREAD * abs(epsilon):
        text += f", varying by {spread * 100:.2g} % between rows (an approximate alias)"
    if "moment_scale" in values and values["moment_scale"]:
        text += f"; here moment_scale ε = {values['moment_scale']['scale_error'] * 100:.3g} %"
    return text


def _thermal_spring(table: MeasurementTable, probes: ProbeSet, values: FittedValues) -> str:
    if not (table.has("temperature_k") and table.has("t_s")) or np.ptp(table.temperature_k) == 0:
        return ""
    correlation = float(np.corrcoef(table.t_s, table.temperature_k)[0, 1])
    if abs(correlation) < LINEAR_CORRELATION:
        return ""
    rate_k_per_s = float(np.polyfit(table.t_s, table.temperature_k, 1)[0])
    text = (
        f"thermal_drift ≡ spring_drift: the temperature rises linearly in time here "
        f"({rate_k_per_s * 3600:.3g} K/h, correlation {correlation:.3f}), so r = α·dT/dt"
    )
    if "thermal_drift" in values and values["thermal_drift"]:
        alpha = values["thermal_drift"]["spring_temp_coeff_per_k"]
        text += f"; here α = {alpha:.3g}/K ≡ spring_drift r = {alpha * rate_k_per_s:.3g}/s"
    elif "spring_drift" in values and values["spring_drift"]:
        rate = values["spring_drift"]["rate_per_s"]
        text += f"; here spring_drift r = {rate:.3g}/s ≡ thermal_drift α = {rate / rate_k_per_s:.3g}/K"
    return text


def _spread(values: np.ndarray) -> float:
    scale = float(np.max(np.abs(values)))
    return float(np.ptp(values)) / scale if scale > 0 else 0.0
