"""The simulator's dynamics: the numba kernels that integrate the probes' motion (docs/physics.md §2, §4).

Equation of motion. The deflection θ_i (θt of Eq. S2) of each probe i of the scene (one probe
is a scene of one) obeys

    J_i·θ_i'' = −U_i'(θ_i, t) − 2J_i·δ_i·θ_i' − Σ_c I_c(t)·W_ic'(θ_i) + τ_stop(θ_i, θ_i') + τ_i,

with U_i(θ, t) = ½·kM_i(T(t))·θ² + W_i(θ) the full potential of docs/physics.md §4 in the static
field at the probe's current pose (gravity included, nothing expanded:
:class:`mows.physics.potential.ArcPotential`), W_ic(θ) = −m_i(θ)·B_c(r_i(θ)) the energy of the
magnet in coil c's field per ampere along the same arc, and I_c(t) = Σ_k A_kc·sin(2πf_k·(t − t_on))
the drive: one tone, or the multi-tone drive of several probes
(:func:`mows.physics.multitone.drive_currents_a`). Free, δ gives the envelope e^(−δt) and the
frequency √(k/J − δ²)/2π of Eqs. S1, S2. kM follows the temperature T(t) = T0 + rate·t.
All derivatives W', W_ic' are Chebyshev series taken from ArcPotential (``d1``), so the torque
is exact to rounding on the whole arc; the drive enters as one series per tone and probe,
Σ_c A_kc·W_ic'.

Coupling. τ_i is the torque of the other magnets' exact dipole fields at their *current*
deflections: with the moment m_i(θ) = m_i·(cos θ·x' + sin θ·y') and position
r_i(θ) = pivot + l_i·m̂_i(θ), the energy −m_i(θ_i)·B_j(r_i(θ_i)) of each neighbour's field B_j gives

    τ_i = Σ_j [∂m_i/∂θ·B_j(r_i) + m_i·G_j(r_i)·∂r_i/∂θ],   ∂r_i/∂θ = (l_i/m_i)·∂m_i/∂θ,

static (the neighbours' rest moments, :mod:`mows.physics.coupling`) and dynamic (their swing,
at their own frequencies) at once. It is written out per component (:func:`_coupling_torques_into`):
it runs at every stage of every step, where numpy's small-array operations cost ~40× more.
One probe has no neighbours and skips it.

Housing stop. At |θ_i| > θstop the housing pushes back as a stiff spring–dashpot contact,
k_c·p + c·ṗ with penetration p = |θ| − θstop, stiffness k_c = ``stiffness_ratio``·kM (1000 by
default: contact ≈ 140 µs, penetration ≈ 0.5° at the impact speeds of a 2 A drive) and
damping c = 2ζ·√(k_c·J), ζ = −ln e/√(π² + ln² e), which gives a linear contact the
coefficient of restitution e. The contact ends when its force would pull (no adhesion), so
the measured restitution is a little above e (0.56 for e = 0.5). A driven probe hammers
against the stop and rings down from there (≈ 24°, the paper's calibrated θmax) when the
coils switch off.

Integrator. Classical RK4 with a fixed step, all probes together: ``substeps`` steps per
sample in free flight and ``contact_substeps`` in every sample in which a probe can reach its
stop. The contact force jumps at the touch (c·ṗ) and has a kink at the release, so every step
that crosses one of these events is cut there: the event instant is found by Newton's method on
the step fraction, and RK4 keeps its fourth order through impacts (trajectories with 16 and 128
contact sub-steps agree to 1e-7 rad). RK4's phase error is (ωh)⁴/120 per radian: at 2 steps
per 50 µs sample and 112 Hz, 8e-10 relative, i.e. 0.1 µHz, far below the 0.01 mHz the
estimator resolves; its energy error, (ωh)⁶/144 per step, acts like a damping of 1e-8 1/s
(tests/sim/test_simulator.py measures both; tests/sim/test_multiprobe_simulation.py the
coupled probes against scipy's solve_ivp). The kernels are compiled by numba once per machine
(``cache=True``, ≈ 6 s of CPU); later processes load them from the cache (:mod:`mows.precompile`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mows.physics.sources import MU0_OVER_4PI

# RK4 is stable for ω·dt below 2.78 on an undamped oscillator; half of that keeps it accurate.
RK4_MAX_OMEGA_DT = 1.4
# In a sample where |θ| + 2|θ'|·Δt + this margin reaches θstop the contact sub-steps are used.
CONTACT_MARGIN_RAD = 1e-3

# The kernel's table: every number the dynamics read, one row per probe, in one contiguous
# array, so that a call in the integrator's loop carries one array, not a dozen (each array
# argument costs more than the torque of one probe). Its columns: the probe's parameters; its
# geometry for the coupling (the moment, the lever, the pivot (3) and the rotation axes x', y'
# (3 each) at the present orientation); the lengths of the series; the Chebyshev coefficients of
# W' (``N_ENV`` of them); then for each of ``N_TONES`` tones its angular frequency followed by
# the coefficients of Σ_c A_kc·W_ic' (``N_DRIVE`` of them). :func:`kernel_table` lays it out.
P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP = range(8)
G_MOMENT, G_LEVER, G_PIVOT, G_X_AXIS, G_Y_AXIS = 8, 9, 10, 13, 16
N_ENV, N_DRIVE, N_TONES = 19, 20, 21
HEAD = 22  # the columns before the series; P_* and G_* are the probe's head, filled by the caller

# Contact mode of the housing stop: FREE, or the side (+1, −1) of the stop in contact.
FREE = 0.0
MAX_EVENTS_PER_STEP = 4  # per probe
EVENT_NEWTON_STEPS = 4
# Rows of the integrator's work array (one column per probe, or per tone): the state and the
# contact modes, the step's end, RK4's stages, and scratch: each lever's direction d and turning
# direction u = ∂d/∂θ (the coupling), each tone's carrier and series (the drive).
_THETA, _OMEGA, _MODE, _NEXT, _A1, _A2, _A3, _A4, _O2, _O3, _O4, _STAGE, _AXES, _CARRIER, _TONE = (
    0,
    1,
    2,
    3,
    5,
    6,
    7,
    8,
    9,
    10,
    11,
    12,
    13,
    19,
    20,
)
_WORK_ROWS = 21


class SimulationRefused(ValueError):
    """A scenario the simulator cannot integrate (a field so strong the lever rings faster than
    the integrator's steps resolve): a bad input, said before the first step."""


def check_resolvable(placed, source, substeps: int, sample_rate_hz: float) -> None:
    """Refuse (SimulationRefused) a field ``source`` whose spring m·|B| makes ω = √((kM + m|B|)/J)
    of one of the probes ``placed`` too fast for the integrator's step 1/(substeps·fs) (Eq. S1
    with the field's spring added)."""
    for p in placed:
        probe = p.probe
        field_t = float(np.linalg.norm(source.field_t(np.asarray(p.pose.magnet_position_m, float))))
        omega = math.sqrt((probe.spring_nm_per_rad + probe.moment_am2 * field_t) / probe.inertia_kgm2)
        omega_dt = omega / (substeps * sample_rate_hz)
        if not omega_dt < RK4_MAX_OMEGA_DT:
            needed = math.ceil(omega / (RK4_MAX_OMEGA_DT * sample_rate_hz))
            raise SimulationRefused(
                f"the field at the probe, |B| = {field_t:.4g} T, makes the lever ring at "
                f"{omega / math.tau:.4g} Hz, "
                f"faster than integrator substeps = {substeps} at {sample_rate_hz:g} S/s resolve "
                f"(ω·dt = {omega_dt:.3g}, must stay below {RK4_MAX_OMEGA_DT}): use a weaker field or "
                f"integrator: substeps ≥ {needed}"
            )


def probe_parameters(probes, environment, housing, half_width_rad: float) -> np.ndarray:
    """(N, HEAD): the head of the kernel's table of ``probes`` in ``environment``
    (:class:`mows.sim.sections.Environment`: the temperature and its rate) and ``housing`` (the
    stop's contact), their potentials represented on ±``half_width_rad``: the P_* columns (the
    geometry, G_*, follows each probe's orientation and is the caller's)."""
    params = np.zeros((len(probes), HEAD))
    for row, probe in zip(params, probes):
        spring_rate = probe.spring_nm_per_rad * probe.spring_temp_coeff_per_k * environment.temperature_rate_k_per_s
        k_stop = housing.stiffness_ratio * probe.spring_nm_per_rad
        log_e = math.log(housing.restitution)
        zeta = -log_e / math.sqrt(math.pi**2 + log_e**2)
        row[[P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP]] = (
            1.0 / probe.inertia_kgm2,
            2.0 * probe.damping_per_s,
            probe.spring_at(environment.temperature_k),
            spring_rate,
            1.0 / half_width_rad,
            probe.theta_stop_rad,
            k_stop,
            2.0 * zeta * math.sqrt(k_stop * probe.inertia_kgm2),
        )
    return params


def kernel_table(head: np.ndarray, env: np.ndarray, drive: np.ndarray, omegas: np.ndarray) -> np.ndarray:
    """The kernel's table of N probes: their ``head`` (N, HEAD) with the P_* and G_* columns,
    W' of the static field ``env`` (N, n_env) and the drive's series ``drive`` (K, N, n_drive) of
    tones of angular frequencies ``omegas`` (K,), rad/s."""
    count, n_env = env.shape
    n_tones, n_drive = drive.shape[0], drive.shape[2]
    table = np.zeros((count, HEAD + n_env + n_tones * (1 + n_drive)))
    table[:, :HEAD] = head
    table[:, N_ENV], table[:, N_DRIVE], table[:, N_TONES] = n_env, n_drive, n_tones
    table[:, HEAD : HEAD + n_env] = env
    for k in range(n_tones):
        column = HEAD + n_env + k * (1 + n_drive)
        table[:, column] = omegas[k]
        table[:, column + 1 : column + 1 + n_drive] = drive[k]
    return table


@njit(cache=True)
def accelerations(theta, omega, t, mode, table, t_on, n_tones):
    """θ'' of every probe at (θ, θ', t) in the contact modes ``mode`` (the equation of motion
    of the module docstring, with the first ``n_tones`` tones of ``table`` switched on at
    ``t_on``) in a new array, for other integrators."""
    count = theta.shape[0]
    work = np.empty((_WORK_ROWS, max(count, n_tones)))
    work[_THETA, :count], work[_OMEGA, :count], work[_MODE, :count] = theta, omega, mode
    _rk4_step(table, work, _THETA, _THETA, t, 0.0, t_on, n_tones, 1)
    return work[_A1, :count].copy()


@njit(cache=True, nogil=True)
def contact_mode(theta, omega, table, i):
    """The mode in which probe i's (θ, θ') lies: in contact while penetrating and the stop
    pushes (never pulls)."""
    side = 1.0 if theta > 0.0 else -1.0
    penetration = side * theta - table[i, P_STOP]
    pushing = table[i, P_K_STOP] * penetration + table[i, P_C_STOP] * side * omega > 0.0
    return side if penetration > 0.0 and pushing else FREE


@njit(cache=True, nogil=True)
def _event(theta, omega, mode, table, i):
    """> 0 while ``mode`` holds for probe i: clearance to the stop when free, the stop's push in contact."""
    if mode == FREE:
        return table[i, P_STOP] - abs(theta)
    return table[i, P_K_STOP] * (mode * theta - table[i, P_STOP]) + table[i, P_C_STOP] * mode * omega


@njit(cache=True, nogil=True)
def _rk4_step(table, work, source, target, t, h, t_on, n_tones, stages=4):
    """One RK4 step of every probe from (θ, θ') in rows ``source``, ``source`` + 1 of ``work``
    into rows ``target``, ``target`` + 1 (which may be the same); with ``stages`` = 1 only θ''
    at the source, into ``work[_A1]``.

    θ'' is the equation of motion of the module docstring, with the first ``n_tones`` tones of
    ``table`` switched on at ``t_on`` (0: coils off), in the contact modes ``work[_MODE]``: in
    contact with side s the stop pushes back with k_c·p + c·ṗ, p = s·θ − θstop. It is written
    out inside the loop over the stages: this is the integrator's innermost loop, where a call
    per stage would cost more than the torque of one probe."""
    count = table.shape[0]
    n_env = int(table[0, N_ENV])
    n_drive = int(table[0, N_DRIVE]) if n_tones > 0 else 0
    first_tone = HEAD + n_env
    theta_row, omega_row, t_stage = source, source + 1, t
    for stage in range(stages):
        for k in range(n_tones):
            work[_CARRIER, k] = math.sin(table[0, first_tone + k * (1 + n_drive)] * (t_stage - t_on))
        if count > 1:
            _coupling_torques_into(table, work, theta_row, _A1 + stage)
        for i in range(count):
            theta, omega = work[theta_row, i], work[omega_row, i]
            x = theta * table[i, P_INV_WIDTH]
            two_x = 2.0 * x
            t_prev, t_cur = 1.0, x
            s_env = table[i, HEAD] + table[i, HEAD + 1] * x
            for j in range(2, n_env):
                t_prev, t_cur = t_cur, two_x * t_cur - t_prev
                s_env += table[i, HEAD + j] * t_cur
            slope = (table[i, P_SPRING0] + table[i, P_SPRING_RATE] * t_stage) * theta + s_env
            for k in range(n_tones):
                column = first_tone + k * (1 + n_drive) + 1
                t_prev, t_cur = 1.0, x
                s_tone = table[i, column] + table[i, column + 1] * x
                for j in range(2, n_drive):
                    t_prev, t_cur = t_cur, two_x * t_cur - t_prev
                    s_tone += table[i, column + j] * t_cur
                slope += work[_CARRIER, k] * s_tone
            side = work[_MODE, i]
            if side != FREE:
                slope += side * (
                    table[i, P_K_STOP] * (side * theta - table[i, P_STOP]) + table[i, P_C_STOP] * side * omega
                )
            if count > 1:
                slope -= work[_A1 + stage, i]
            work[_A1 + stage, i] = -slope * table[i, P_INV_INERTIA] - table[i, P_TWO_DELTA] * omega
        if stage == stages - 1:
            break
        # the next stage's state: θ + c·θ'_s, θ' + c·θ''_s, with c = h/2, h/2, h
        fraction = 1.0 if stage == 2 else 0.5
        for i in range(count):
            work[_STAGE, i] = work[source, i] + fraction * h * work[omega_row, i]
            work[_O2 + stage, i] = work[source + 1, i] + fraction * h * work[_A1 + stage, i]
        theta_row, omega_row, t_stage = _STAGE, _O2 + stage, t + fraction * h
    if stages < 4:
        return
    for i in range(count):
        theta, omega = work[source, i], work[source + 1, i]
        work[target, i] = theta + h / 6.0 * (omega + 2.0 * work[_O2, i] + 2.0 * work[_O3, i] + work[_O4, i])
        work[target + 1, i] = omega + h / 6.0 * (work[_A1, i] + 2.0 * work[_A2, i] + 2.0 * work[_A3, i] + work[_A4, i])


@njit(cache=True, nogil=True)
def _step(table, work, t, h, t_on, n_tones):
    """One RK4 step of length h of every probe, in place in rows ``_THETA``, ``_OMEGA`` of
    ``work``, that stops at every change of a probe's contact mode inside it.

    Within a mode the force is smooth, so RK4 keeps its order across impacts: the instant
    where :func:`_event` of the probe that changes first reaches zero is found by Newton's
    method on the step fraction, the step is taken up to it, that probe's mode switches, and
    the rest of the step follows.
    """
    count = table.shape[0]
    for _ in range(MAX_EVENTS_PER_STEP * count):
        for i in range(count):
            if _event(work[_THETA, i], work[_OMEGA, i], work[_MODE, i], table, i) < 0.0:
                # The mode no longer holds (an event located just past its instant, e.g. a grazing
                # contact whose push turns negative at once): take the mode the state lies in.
                # Without this a contact could go on pulling, gluing the probe to the stop.
                work[_MODE, i] = contact_mode(work[_THETA, i], work[_OMEGA, i], table, i)
        _rk4_step(table, work, _THETA, _NEXT, t, h, t_on, n_tones)
        first, fraction = -1, 2.0
        for i in range(count):
            g0 = _event(work[_THETA, i], work[_OMEGA, i], work[_MODE, i], table, i)
            g1 = _event(work[_NEXT, i], work[_NEXT + 1, i], work[_MODE, i], table, i)
            if g0 >= 0.0 and g1 < 0.0 and g0 / (g0 - g1) < fraction:
                first, fraction = i, g0 / (g0 - g1)
        if first < 0:
            for i in range(count):
                work[_THETA, i], work[_OMEGA, i] = work[_NEXT, i], work[_NEXT + 1, i]
            return
        side = work[_MODE, first]
        for _ in range(EVENT_NEWTON_STEPS):
            _rk4_step(table, work, _THETA, _NEXT, t, fraction * h, t_on, n_tones)
            theta1, omega1 = work[_NEXT, first], work[_NEXT + 1, first]
            # d/dt of the event along the motion
            if side == FREE:
                rate = -omega1 if theta1 > 0.0 else omega1
            else:
                _rk4_step(table, work, _NEXT, _NEXT, t + fraction * h, 0.0, t_on, n_tones, 1)
                rate = side * (table[first, P_K_STOP] * omega1 + table[first, P_C_STOP] * work[_A1, first])
            if rate == 0.0:
                break
            fraction = min(max(fraction - _event(theta1, omega1, side, table, first) / (rate * h), 0.0), 1.0)
        _rk4_step(table, work, _THETA, _THETA, t, fraction * h, t_on, n_tones)
        t += fraction * h
        h -= fraction * h
        work[_MODE, first] = (1.0 if work[_THETA, first] > 0.0 else -1.0) if side == FREE else FREE
    _rk4_step(table, work, _THETA, _THETA, t, h, t_on, n_tones)


@njit(cache=True, nogil=True)  # the driver's executor answers requests while it runs
def advance(state, table, first_index, sample_rate_hz, substeps, contact_substeps, t_on, n_tones, theta_out, omega_out):
    """Record (θ, θ') of every probe at samples first_index … first_index + n − 1 into rows of
    ``theta_out`` and ``omega_out`` (n, N) and integrate to the next, with the first ``n_tones``
    tones of ``table`` switched on at ``t_on``.

    ``state`` (3, N) = [θ, θ', contact mode] is updated in place. Returns the number of samples
    done; fewer than n if a θ left its Chebyshev interval (|x| > 1), where the series is no
    longer the potential.
    """
    count = table.shape[0]
    work = np.empty((_WORK_ROWS, max(count, n_tones)))
    for row in range(3):
        for i in range(count):
            work[row, i] = state[row, i]
    dt = 1.0 / sample_rate_hz
    done = theta_out.shape[0]
    for sample in range(theta_out.shape[0]):
        outside = False
        for i in range(count):
            outside = outside or abs(work[_THETA, i]) * table[i, P_INV_WIDTH] > 1.0
        if outside:
            done = sample
            break
        near = False
        for i in range(count):
            theta, omega = work[_THETA, i], work[_OMEGA, i]
            theta_out[sample, i] = theta
            omega_out[sample, i] = omega
            near = (
                near
                or work[_MODE, i] != FREE
                or abs(theta) + 2.0 * abs(omega) * dt + CONTACT_MARGIN_RAD >= table[i, P_STOP]
            )
        t = (first_index + sample) * dt
        steps = contact_substeps if near else substeps
        h = dt / steps
        for k in range(steps):
            _step(table, work, t + k * h, h, t_on, n_tones)
    for row in range(3):
        for i in range(count):
            state[row, i] = work[row, i]
    return done


@njit(cache=True, nogil=True)
def _coupling_torques_into(table, work, theta_row, out_row):
    """τ_i of the module docstring into ``work[out_row]`` at θ = ``work[theta_row]``, with the
    dipole field of magnet j at r = r_i − r_j, B = μ0/(4π)·[3r(m_j·r)/r⁵ − m_j/r³], and its
    gradient along v = ∂r_i/∂θ, G·v = 3μ0/(4π r⁵)·[m_j(r·v) + r(m_j·v) + (m_j·r)v − 5(m_j·r)(r·v)r/r²]
    (the expressions of :class:`mows.physics.sources.PointDipole`)."""
    count = table.shape[0]
    for i in range(count):
        c, s = math.cos(work[theta_row, i]), math.sin(work[theta_row, i])
        for k in range(3):
            x_k, y_k = table[i, G_X_AXIS + k], table[i, G_Y_AXIS + k]
            work[_AXES + k, i] = c * x_k + s * y_k
            work[_AXES + 3 + k, i] = -s * x_k + c * y_k
    for i in range(count):
        lever = table[i, G_LEVER]
        dx, dy, dz = work[_AXES, i], work[_AXES + 1, i], work[_AXES + 2, i]
        ux, uy, uz = work[_AXES + 3, i], work[_AXES + 4, i], work[_AXES + 5, i]
        vx, vy, vz = lever * ux, lever * uy, lever * uz
        rix = table[i, G_PIVOT] + lever * dx
        riy = table[i, G_PIVOT + 1] + lever * dy
        riz = table[i, G_PIVOT + 2] + lever * dz
        total = 0.0
        for j in range(count):
            if j == i:
                continue
            ex, ey, ez = work[_AXES, j], work[_AXES + 1, j], work[_AXES + 2, j]
            moment, lever_j = table[j, G_MOMENT], table[j, G_LEVER]
            mx, my, mz = moment * ex, moment * ey, moment * ez
            rx = rix - (table[j, G_PIVOT] + lever_j * ex)
            ry = riy - (table[j, G_PIVOT + 1] + lever_j * ey)
            rz = riz - (table[j, G_PIVOT + 2] + lever_j * ez)
            r2 = rx * rx + ry * ry + rz * rz
            inv_r3 = r2**-1.5
            mr, rv, mv = mx * rx + my * ry + mz * rz, rx * vx + ry * vy + rz * vz, mx * vx + my * vy + mz * vz
            a, b = 3.0 * mr * inv_r3 / r2, inv_r3
            fx, fy, fz = a * rx - b * mx, a * ry - b * my, a * rz - b * mz
            g, q = 3.0 * inv_r3 / r2, 5.0 * mr * rv / r2
            gx = g * (mx * rv + rx * mv + mr * vx - q * rx)
            gy = g * (my * rv + ry * mv + mr * vy - q * ry)
            gz = g * (mz * rv + rz * mv + mr * vz - q * rz)
            # dm_i·B + m_i·(G·v), with m_i = moment_i·d and dm_i = moment_i·u; μ0/4π taken out of both
            total += ux * fx + uy * fy + uz * fz + dx * gx + dy * gy + dz * gz
        work[out_row, i] = MU0_OVER_4PI * table[i, G_MOMENT] * total


@njit(cache=True)
def coupling_torques(theta, table):
    """τ_i of every probe (:func:`_coupling_torques_into`) in a new array."""
    count = theta.shape[0]
    work = np.empty((_WORK_ROWS, count))
    work[_THETA] = theta
    _coupling_torques_into(table, work, _THETA, _A1)
    return work[_A1].copy()
