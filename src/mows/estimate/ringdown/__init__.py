"""The ring-down fit: one free ring-down fitted at the Cramér–Rao bound, and several probes
ringing down together in one window fitted jointly.

``fit`` (:func:`fit_ringdown`, the model and the estimator in its docstring), ``types`` (its
:class:`FitOptions`, :class:`RingdownFit`, :class:`FitStatus`), ``problem`` (variable projection,
the Fisher information, the bound), ``start`` (the noise level and the spectral start),
``offset`` (the rest offset and θmax searched over their whole range), ``model`` (the compiled
kernels) and ``joint`` (:func:`mows.estimate.ringdown.joint.fit_ringdowns`, several probes in
one window). Each imports only those before it in the order model, types, problem, start,
offset, fit, joint.

This package's ``__init__`` re-exports the single fit's public names:
``from mows.estimate.ringdown import fit_ringdown, FitOptions``.

May import: ``mows.physics``, ``mows.records``; nothing else of ``mows.estimate``.
"""

from mows.estimate.ringdown.fit import (
    COIL_OFF_SKIP_S,
    DETERMINED_SIGMAS,
    RIVAL_CHI2,
    combine_channels,
    fit_ringdown,
    starting_point,
    usable_window,
    wrapped_rad,
)
from mows.estimate.ringdown.types import FitOptions, FitStatus, RingdownFit, failure, parameter_std

__all__ = [
    "COIL_OFF_SKIP_S",
    "DETERMINED_SIGMAS",
    "RIVAL_CHI2",
    "FitOptions",
    "FitStatus",
    "RingdownFit",
    "combine_channels",
    "failure",
    "fit_ringdown",
    "parameter_std",
    "starting_point",
    "usable_window",
    "wrapped_rad",
]
