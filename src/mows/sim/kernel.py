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
at their own frequencies) at once. It is written out per component (:func:`coupling_torques_into`):
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
(tests/physics/test_simulator.py measures both; tests/physics/test_multiprobe_simulation.py the
coupled probes against scipy's solve_ivp). The kernels are compiled by numba once per machine
(``cache=True``, ≈ 1 s); later processes load them from the cache (:mod:`mows.precompile`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mows.physics.sources import MU0_OVER_4PI

TWO_PI = 2.0 * math.pi

# In a sample where |θ| + 2|θ'|·Δt + this margin reaches θstop the contact sub-steps are used.
CONTACT_MARGIN_RAD = 1e-3

# Columns of the kernel's parameters, one row per probe (one array keeps numba's signature short).
P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP = range(8)
N_PARAMS = 8
# Columns of the probes' geometry for the coupling, one row per probe: the moment, the lever,
# the pivot (3) and the rotation axes x', y' (3 each) at the present orientation.
G_MOMENT, G_LEVER, G_PIVOT, G_X_AXIS, G_Y_AXIS = 0, 1, 2, 5, 8
N_GEOMETRY = 11

# Contact mode of the housing stop: FREE, or the side (+1, −1) of the stop in contact.
FREE = 0.0
MAX_EVENTS_PER_STEP = 4  # per probe
EVENT_NEWTON_STEPS = 4
# Rows of the integrator's work array: the state, the step's end, RK4's stages.
_THETA, _OMEGA, _NEXT, _A1, _A2, _A3, _A4, _O2, _O3, _O4, _STAGE = 0, 1, 2, 4, 5, 6, 7, 8, 9, 10, 11
_WORK_ROWS = 12


@njit(cache=True, nogil=True)
def acceleration_into(
    work, theta_row, omega_row, t, mode, params, env, drive, omegas, t_on, geometry, axes, tones, out_row
):
    """θ_i'' of every probe at (θ, θ', t) = (``work[theta_row]``, ``work[omega_row]``, t) in
    contact ``mode`` into ``work[out_row]``: the equation of motion of the module docstring.

    ``env`` (N, n) holds the Chebyshev coefficients of W_i' in x = θ/w, ``drive`` (K, N, n) those
    of Σ_c A_kc·W_ic' for each tone k of angular frequency ``omegas[k]`` switched on at ``t_on``
    (K = 0 with the coils off). In contact with side s = ``mode[i]`` the stop pushes back with
    k_c·p + c·ṗ, p = s·θ − θstop. ``axes`` (N, 6) and ``tones`` (2, K) are scratch. The states
    are rows of one array, indexed in place: views and tuples of arrays would cost a reference
    count each, more than the torque itself for one probe.
    """
    count = work.shape[1]
    n_env = env.shape[1]
    n_tones = drive.shape[0]
    n_drive = drive.shape[2] if n_tones > 0 else 0
    for k in range(n_tones):
        tones[0, k] = math.sin(omegas[k] * (t - t_on))
    if count > 1:
        coupling_torques_into(work, theta_row, geometry, axes, out_row)
    for i in range(count):
        theta, omega = work[theta_row, i], work[omega_row, i]
        x = theta * params[i, P_INV_WIDTH]
        t_prev, t_cur = 1.0, x
        s_env = env[i, 0] + env[i, 1] * x
        for k in range(n_tones):
            tones[1, k] = drive[k, i, 0] + drive[k, i, 1] * x
        for j in range(2, max(n_env, n_drive)):
            t_prev, t_cur = t_cur, 2.0 * x * t_cur - t_prev
            if j < n_env:
                s_env += env[i, j] * t_cur
            if j < n_drive:
                for k in range(n_tones):
                    tones[1, k] += drive[k, i, j] * t_cur
        slope = (params[i, P_SPRING0] + params[i, P_SPRING_RATE] * t) * theta + s_env
        for k in range(n_tones):
            slope += tones[0, k] * tones[1, k]
        side = mode[i]
        if side != FREE:
            slope += side * (
                params[i, P_K_STOP] * (side * theta - params[i, P_STOP]) + params[i, P_C_STOP] * side * omega
            )
        if count > 1:
            slope -= work[out_row, i]
        work[out_row, i] = -slope * params[i, P_INV_INERTIA] - params[i, P_TWO_DELTA] * omega


@njit(cache=True)
def accelerations(theta, omega, t, mode, params, env, drive, omegas, t_on, geometry):
    """θ'' of every probe (:func:`acceleration_into`) in a new array, for other integrators."""
    work = np.empty((3, theta.shape[0]))
    work[0], work[1] = theta, omega
    axes, tones = np.empty((theta.shape[0], 6)), np.empty((2, drive.shape[0]))
    acceleration_into(work, 0, 1, t, mode, params, env, drive, omegas, t_on, geometry, axes, tones, 2)
    return work[2].copy()


@njit(cache=True, nogil=True)
def contact_mode(theta, omega, params, i):
    """The mode in which probe i's (θ, θ') lies: in contact while penetrating and the stop
    pushes (never pulls)."""
    side = 1.0 if theta > 0.0 else -1.0
    penetration = side * theta - params[i, P_STOP]
    pushing = params[i, P_K_STOP] * penetration + params[i, P_C_STOP] * side * omega > 0.0
    return side if penetration > 0.0 and pushing else FREE


@njit(cache=True, nogil=True)
def _event(theta, omega, mode, params, i):
    """> 0 while ``mode`` holds for probe i: clearance to the stop when free, the stop's push in contact."""
    if mode == FREE:
        return params[i, P_STOP] - abs(theta)
    return params[i, P_K_STOP] * (mode * theta - params[i, P_STOP]) + params[i, P_C_STOP] * mode * omega


@njit(cache=True, nogil=True)
def _rk4_step(work, source, target, t, h, mode, params, env, drive, omegas, t_on, geometry, axes, tones):
    """One RK4 step of every probe from (θ, θ') in rows ``source``, ``source`` + 1 of ``work``
    into rows ``target``, ``target`` + 1 (which may be the same)."""
    count = work.shape[1]
    th, om = source, source + 1
    acceleration_into(work, th, om, t, mode, params, env, drive, omegas, t_on, geometry, axes, tones, _A1)
    for i in range(count):
        work[_O2, i] = work[om, i] + 0.5 * h * work[_A1, i]
        work[_STAGE, i] = work[th, i] + 0.5 * h * work[om, i]
    acceleration_into(
        work, _STAGE, _O2, t + 0.5 * h, mode, params, env, drive, omegas, t_on, geometry, axes, tones, _A2
    )
    for i in range(count):
        work[_O3, i] = work[om, i] + 0.5 * h * work[_A2, i]
        work[_STAGE, i] = work[th, i] + 0.5 * h * work[_O2, i]
    acceleration_into(
        work, _STAGE, _O3, t + 0.5 * h, mode, params, env, drive, omegas, t_on, geometry, axes, tones, _A3
    )
    for i in range(count):
        work[_O4, i] = work[om, i] + h * work[_A3, i]
        work[_STAGE, i] = work[th, i] + h * work[_O3, i]
    acceleration_into(work, _STAGE, _O4, t + h, mode, params, env, drive, omegas, t_on, geometry, axes, tones, _A4)
    for i in range(count):
        theta, omega = work[th, i], work[om, i]
        work[target, i] = theta + h / 6.0 * (omega + 2.0 * work[_O2, i] + 2.0 * work[_O3, i] + work[_O4, i])
        work[target + 1, i] = omega + h / 6.0 * (work[_A1, i] + 2.0 * work[_A2, i] + 2.0 * work[_A3, i] + work[_A4, i])


@njit(cache=True, nogil=True)
def _step(work, t, h, mode, params, env, drive, omegas, t_on, geometry, axes, tones):
    """One RK4 step of length h of every probe, in place in rows ``_THETA``, ``_OMEGA`` of
    ``work``, that stops at every change of a probe's contact mode inside it.

    Within a mode the force is smooth, so RK4 keeps its order across impacts: the instant
    where :func:`_event` of the probe that changes first reaches zero is found by Newton's
    method on the step fraction, the step is taken up to it, that probe's mode switches, and
    the rest of the step follows.
    """
    count = work.shape[1]
    for _ in range(MAX_EVENTS_PER_STEP * count):
        for i in range(count):
            if _event(work[_THETA, i], work[_OMEGA, i], mode[i], params, i) < 0.0:
                # The mode no longer holds (an event located just past its instant, e.g. a grazing
                # contact whose push turns negative at once): take the mode the state lies in.
                # Without this a contact could go on pulling, gluing the probe to the stop.
                mode[i] = contact_mode(work[_THETA, i], work[_OMEGA, i], params, i)
        _rk4_step(work, _THETA, _NEXT, t, h, mode, params, env, drive, omegas, t_on, geometry, axes, tones)
        first, fraction = -1, 2.0
        for i in range(count):
            g0 = _event(work[_THETA, i], work[_OMEGA, i], mode[i], params, i)
            g1 = _event(work[_NEXT, i], work[_NEXT + 1, i], mode[i], params, i)
            if g0 >= 0.0 and g1 < 0.0 and g0 / (g0 - g1) < fraction:
                first, fraction = i, g0 / (g0 - g1)
        if first < 0:
            for i in range(count):
                work[_THETA, i], work[_OMEGA, i] = work[_NEXT, i], work[_NEXT + 1, i]
            return
        side = mode[first]
        for _ in range(EVENT_NEWTON_STEPS):
            _rk4_step(
                work, _THETA, _NEXT, t, fraction * h, mode, params, env, drive, omegas, t_on, geometry, axes, tones
            )
            theta1, omega1 = work[_NEXT, first], work[_NEXT + 1, first]
            # d/dt of the event along the motion
            if side == FREE:
                rate = -omega1 if theta1 > 0.0 else omega1
            else:
                acceleration_into(
                    work,
                    _NEXT,
                    _NEXT + 1,
                    t + fraction * h,
                    mode,
                    params,
                    env,
                    drive,
                    omegas,
                    t_on,
                    geometry,
                    axes,
                    tones,
                    _A1,
                )
                rate = side * (params[first, P_K_STOP] * omega1 + params[first, P_C_STOP] * work[_A1, first])
            if rate == 0.0:
                break
            fraction = min(max(fraction - _event(theta1, omega1, side, params, first) / (rate * h), 0.0), 1.0)
        _rk4_step(work, _THETA, _THETA, t, fraction * h, mode, params, env, drive, omegas, t_on, geometry, axes, tones)
        t += fraction * h
        h -= fraction * h
        mode[first] = (1.0 if work[_THETA, first] > 0.0 else -1.0) if side == FREE else FREE
    _rk4_step(work, _THETA, _THETA, t, h, mode, params, env, drive, omegas, t_on, geometry, axes, tones)


@njit(cache=True, nogil=True)  # the driver's executor answers requests while it runs
def advance(
    state,
    first_index,
    sample_rate_hz,
    substeps,
    contact_substeps,
    params,
    env,
    drive,
    omegas,
    t_on,
    geometry,
    theta_out,
    omega_out,
):
    """Record (θ, θ') of every probe at samples first_index … first_index + n − 1 into rows of
    ``theta_out`` and ``omega_out`` (n, N) and integrate to the next.

    ``state`` (3, N) = [θ, θ', contact mode] is updated in place. Returns the number of samples
    done; fewer than n if a θ left its Chebyshev interval (|x| > 1), where the series is no
    longer the potential.
    """
    count = state.shape[1]
    work = np.empty((_WORK_ROWS, count))
    work[_THETA], work[_OMEGA] = state[0], state[1]
    mode = state[2]
    axes, tones = np.empty((count, 6)), np.empty((2, drive.shape[0]))
    dt = 1.0 / sample_rate_hz
    done = theta_out.shape[0]
    for sample in range(theta_out.shape[0]):
        outside = False
        for i in range(count):
            outside = outside or abs(work[_THETA, i]) * params[i, P_INV_WIDTH] > 1.0
        if outside:
            done = sample
            break
        near = False
        for i in range(count):
            theta, omega = work[_THETA, i], work[_OMEGA, i]
            theta_out[sample, i] = theta
            omega_out[sample, i] = omega
            near = (
                near or mode[i] != FREE or abs(theta) + 2.0 * abs(omega) * dt + CONTACT_MARGIN_RAD >= params[i, P_STOP]
            )
        t = (first_index + sample) * dt
        steps = contact_substeps if near else substeps
        h = dt / steps
        for k in range(steps):
            _step(work, t + k * h, h, mode, params, env, drive, omegas, t_on, geometry, axes, tones)
    state[0], state[1] = work[_THETA], work[_OMEGA]
    return done


@njit(cache=True, nogil=True)
def coupling_torques_into(work, theta_row, geometry, axes, out_row):
    """τ_i of the module docstring into ``torque``, with the dipole field of magnet j at
    r = r_i − r_j, B = μ0/(4π)·[3r(m_j·r)/r⁵ − m_j/r³], and its gradient along v = ∂r_i/∂θ,
    G·v = 3μ0/(4π r⁵)·[m_j(r·v) + r(m_j·v) + (m_j·r)v − 5(m_j·r)(r·v)r/r²]
    (the expressions of :class:`mows.physics.sources.PointDipole`). ``axes`` (N, 6) is scratch
    for each lever's direction d and turning direction u = ∂d/∂θ. θ is ``work[theta_row]``, τ
    goes to ``work[out_row]``."""
    count = work.shape[1]
    for i in range(count):
        c, s = math.cos(work[theta_row, i]), math.sin(work[theta_row, i])
        for k in range(3):
            x_k, y_k = geometry[i, G_X_AXIS + k], geometry[i, G_Y_AXIS + k]
            axes[i, k] = c * x_k + s * y_k
            axes[i, 3 + k] = -s * x_k + c * y_k
    for i in range(count):
        lever = geometry[i, G_LEVER]
        dx, dy, dz, ux, uy, uz = axes[i, 0], axes[i, 1], axes[i, 2], axes[i, 3], axes[i, 4], axes[i, 5]
        vx, vy, vz = lever * ux, lever * uy, lever * uz
        rix = geometry[i, G_PIVOT] + lever * dx
        riy = geometry[i, G_PIVOT + 1] + lever * dy
        riz = geometry[i, G_PIVOT + 2] + lever * dz
        total = 0.0
        for j in range(count):
            if j == i:
                continue
            ex, ey, ez = axes[j, 0], axes[j, 1], axes[j, 2]
            moment, lever_j = geometry[j, G_MOMENT], geometry[j, G_LEVER]
            mx, my, mz = moment * ex, moment * ey, moment * ez
            rx = rix - (geometry[j, G_PIVOT] + lever_j * ex)
            ry = riy - (geometry[j, G_PIVOT + 1] + lever_j * ey)
            rz = riz - (geometry[j, G_PIVOT + 2] + lever_j * ez)
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
        work[out_row, i] = MU0_OVER_4PI * geometry[i, G_MOMENT] * total


@njit(cache=True)
def coupling_torques(theta, geometry):
    """τ_i of every probe (:func:`coupling_torques_into`) in a new array."""
    work = np.empty((2, theta.shape[0]))
    work[0] = theta
    coupling_torques_into(work, 0, geometry, np.empty((theta.shape[0], 6)), 1)
    return work[1].copy()
