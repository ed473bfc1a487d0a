"""The simulator's dynamics: the numba kernels that integrate the probe's motion (docs/physics.md §2, §4).

Equation of motion. The deflection θ (θt of Eq. S2) obeys

    J·θ'' = −U'(θ, t) − 2J·δ·θ' − Σ_k I_k(t)·W_k'(θ) + τ_stop(θ, θ'),

with U(θ, t) = ½·kM(T(t))·θ² + W(θ) the full potential of docs/physics.md §4 in the environment
field at the current pose (gravity included, nothing expanded: :class:`mows.physics.potential.ArcPotential`),
W_k(θ) = −m(θ)·B_k(r(θ)) the energy of the magnet in coil k's field per ampere along the same
arc, and I_k(t) = A_k·sin(2πf·(t − t_on)) the drive. Free, δ gives the envelope e^(−δt) and the
frequency √(k/J − δ²)/2π of Eqs. S1, S2. kM follows the temperature T(t) = T0 + rate·t.
All derivatives W', W_k' are Chebyshev series taken from ArcPotential (``d1``), so the torque
is exact to rounding on the whole arc.

Housing stop. At |θ| > θstop the housing pushes back as a stiff spring–dashpot contact,
k_c·p + c·ṗ with penetration p = |θ| − θstop, stiffness k_c = ``stiffness_ratio``·kM (1000 by
default: contact ≈ 140 µs, penetration ≈ 0.5° at the impact speeds of a 2 A drive) and
damping c = 2ζ·√(k_c·J), ζ = −ln e/√(π² + ln² e), which gives a linear contact the
coefficient of restitution e. The contact ends when its force would pull (no adhesion), so
the measured restitution is a little above e (0.56 for e = 0.5). A driven probe hammers
against the stop and rings down from there (≈ 24°, the paper's calibrated θmax) when the
coils switch off.

Integrator. Classical RK4 with a fixed step: ``substeps`` steps per sample in free flight
and ``contact_substeps`` in every sample in which the stop can be reached. The contact force
jumps at the touch (c·ṗ) and has a kink at the release, so every step that crosses one of
these events is cut there: the event instant is found by Newton's method on the step
fraction, and RK4 keeps its fourth order through impacts (trajectories with 16 and 128
contact sub-steps agree to 1e-7 rad). RK4's phase error is (ωh)⁴/120 per radian: at 2 steps
per 50 µs sample and 112 Hz, 8e-10 relative, i.e. 0.1 µHz, far below the 0.01 mHz the
estimator resolves; its energy error, (ωh)⁶/144 per step, acts like a damping of 1e-8 1/s
(tests/physics/test_simulator.py measures both). The kernel is compiled by numba once per
machine (``cache=True``, ≈ 1 s); later processes load it from the cache.

"""

from __future__ import annotations

import math

from numba import njit

TWO_PI = 2.0 * math.pi

# In a sample where |θ| + 2|θ'|·Δt + this margin reaches θstop the contact sub-steps are used.
CONTACT_MARGIN_RAD = 1e-3

# Parameter vector of the kernel (one array keeps numba's signature short).
P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP = range(8)


# Contact mode of the housing stop: FREE, or the side (+1, −1) of the stop in contact.
FREE = 0.0
MAX_EVENTS_PER_STEP = 4
EVENT_NEWTON_STEPS = 4


@njit(cache=True)
def acceleration(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0):
    """θ'' at (θ, θ', t) in contact ``mode``: the equation of motion of the module docstring.

    ``env`` and ``drive`` hold Chebyshev coefficients of W' and Σ_k A_k·W_k' in x = θ/w
    (``drive`` is empty when the coils are off). In contact with side s = ``mode`` the stop
    pushes back with k_c·p + c·ṗ, p = s·θ − θstop.
    """
    x = theta * params[P_INV_WIDTH]
    t_prev, t_cur = 1.0, x
    s_env = env[0] + env[1] * x
    n_drive = drive.shape[0]
    s_drive = drive[0] + drive[1] * x if n_drive > 0 else 0.0
    for j in range(2, max(env.shape[0], n_drive)):
        t_prev, t_cur = t_cur, 2.0 * x * t_cur - t_prev
        if j < env.shape[0]:
            s_env += env[j] * t_cur
        if j < n_drive:
            s_drive += drive[j] * t_cur
    slope = (params[P_SPRING0] + params[P_SPRING_RATE] * t) * theta + s_env
    if n_drive > 0:
        slope += math.sin(drive_omega * (t - drive_t0)) * s_drive
    if mode != FREE:
        slope += mode * (params[P_K_STOP] * (mode * theta - params[P_STOP]) + params[P_C_STOP] * mode * omega)
    return -slope * params[P_INV_INERTIA] - params[P_TWO_DELTA] * omega


@njit(cache=True)
def contact_mode(theta, omega, params):
    """The mode in which (θ, θ') lies: in contact while penetrating and the stop pushes (never pulls)."""
    side = 1.0 if theta > 0.0 else -1.0
    penetration = side * theta - params[P_STOP]
    pushing = params[P_K_STOP] * penetration + params[P_C_STOP] * side * omega > 0.0
    return side if penetration > 0.0 and pushing else FREE


@njit(cache=True)
def _event(theta, omega, mode, params):
    """> 0 while ``mode`` holds: clearance to the stop when free, the stop's push in contact."""
    if mode == FREE:
        return params[P_STOP] - abs(theta)
    return params[P_K_STOP] * (mode * theta - params[P_STOP]) + params[P_C_STOP] * mode * omega


@njit(cache=True)
def _event_rate(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0):
    """d/dt of :func:`_event` along the motion."""
    if mode == FREE:
        return -omega if theta > 0.0 else omega
    a = acceleration(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0)
    return mode * (params[P_K_STOP] * omega + params[P_C_STOP] * a)


@njit(cache=True)
def _rk4_step(theta, omega, t, h, mode, params, env, drive, drive_omega, drive_t0):
    a1 = acceleration(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0)
    o2 = omega + 0.5 * h * a1
    a2 = acceleration(theta + 0.5 * h * omega, o2, t + 0.5 * h, mode, params, env, drive, drive_omega, drive_t0)
    o3 = omega + 0.5 * h * a2
    a3 = acceleration(theta + 0.5 * h * o2, o3, t + 0.5 * h, mode, params, env, drive, drive_omega, drive_t0)
    o4 = omega + h * a3
    a4 = acceleration(theta + h * o3, o4, t + h, mode, params, env, drive, drive_omega, drive_t0)
    return (theta + h / 6.0 * (omega + 2.0 * o2 + 2.0 * o3 + o4), omega + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4))


@njit(cache=True)
def _step(theta, omega, mode, t, h, params, env, drive, drive_omega, drive_t0):
    """One RK4 step of length h that stops at every change of contact mode inside it.

    Within a mode the force is smooth, so RK4 keeps its order across impacts: the instant
    where :func:`_event` reaches zero is found by Newton's method on the step fraction, the
    step is taken up to it, the mode switches, and the rest of the step follows.
    """
    for _ in range(MAX_EVENTS_PER_STEP):
        if _event(theta, omega, mode, params) < 0.0:
            # The mode no longer holds (an event located just past its instant, e.g. a grazing
            # contact whose push turns negative at once): take the mode the state lies in.
            # Without this a contact could go on pulling, gluing the probe to the stop.
            mode = contact_mode(theta, omega, params)
        theta1, omega1 = _rk4_step(theta, omega, t, h, mode, params, env, drive, drive_omega, drive_t0)
        g0 = _event(theta, omega, mode, params)
        g1 = _event(theta1, omega1, mode, params)
        if not (g0 >= 0.0 and g1 < 0.0):
            return theta1, omega1, mode
        fraction = g0 / (g0 - g1)
        for _ in range(EVENT_NEWTON_STEPS):
            theta1, omega1 = _rk4_step(theta, omega, t, fraction * h, mode, params, env, drive, drive_omega, drive_t0)
            rate = _event_rate(theta1, omega1, t + fraction * h, mode, params, env, drive, drive_omega, drive_t0)
            if rate == 0.0:
                break
            fraction = min(max(fraction - _event(theta1, omega1, mode, params) / (rate * h), 0.0), 1.0)
        theta, omega = _rk4_step(theta, omega, t, fraction * h, mode, params, env, drive, drive_omega, drive_t0)
        t += fraction * h
        h -= fraction * h
        mode = (1.0 if theta > 0.0 else -1.0) if mode == FREE else FREE
    return _rk4_step(theta, omega, t, h, mode, params, env, drive, drive_omega, drive_t0) + (mode,)


@njit(cache=True)
def advance(
    state,
    first_index,
    sample_rate_hz,
    substeps,
    contact_substeps,
    params,
    env,
    drive,
    drive_omega,
    drive_t0,
    theta_out,
    omega_out,
):
    """Record (θ, θ') at samples first_index … first_index + n − 1 and integrate to the next.

    ``state`` = [θ, θ', contact mode] is updated in place. Returns the number of samples done;
    fewer than n if θ left the Chebyshev interval (|x| > 1), where the series is no longer
    the potential.
    """
    theta, omega, mode = state[0], state[1], state[2]
    dt = 1.0 / sample_rate_hz
    for i in range(theta_out.shape[0]):
        if abs(theta) * params[P_INV_WIDTH] > 1.0:
            state[0], state[1], state[2] = theta, omega, mode
            return i
        theta_out[i] = theta
        omega_out[i] = omega
        t = (first_index + i) * dt
        near = mode != FREE or abs(theta) + 2.0 * abs(omega) * dt + CONTACT_MARGIN_RAD >= params[P_STOP]
        steps = contact_substeps if near else substeps
        h = dt / steps
        for k in range(steps):
            theta, omega, mode = _step(theta, omega, mode, t + k * h, h, params, env, drive, drive_omega, drive_t0)
    state[0], state[1], state[2] = theta, omega, mode
    return theta_out.shape[0]
