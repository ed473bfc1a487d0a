"""The ring-down fit: K ≥ 1 probes ringing down in one window, fitted jointly at the
Cramér–Rao bound; one probe is the group of one.

``fit`` (:func:`fit_ringdowns`, and :func:`fit_ringdown` for one probe; the model and the
estimator in its docstring), ``types`` (:class:`FitOptions`, :class:`ProbeLine`,
:class:`RingdownFit`, :class:`FitStatus`), ``model`` (the compiled kernels), ``problem``
(variable projection, Levenberg–Marquardt, the Fisher information, the bound), ``start`` (the
noise level and the spectral start), ``offset`` (one probe's rest offset and θmax searched over
their whole range), ``summary`` (the covariance, the bound and what the data do not determine,
into one :class:`RingdownFit` per probe), ``absent`` (a probe whose line is not in the data),
``window`` (the samples the fit sees). Each imports only those before it in the order
model, types, problem, start, offset, summary, absent, window, fit.

This package's ``__init__`` re-exports the fit's public names:
``from mows.estimate.ringdown import fit_ringdown, FitOptions``.

May import: ``mows.physics``, ``mows.records``; nothing else of ``mows.estimate``.
"""

from mows.estimate.ringdown.fit import fit_ringdown, fit_ringdowns, fit_tuning, starting_point
from mows.estimate.ringdown.problem import cramer_rao_frequency_hz, cramer_rao_hz
from mows.estimate.ringdown.summary import DETERMINED_SIGMAS, RIVAL_CHI2, swing_from_signal_rad, wrapped_rad
from mows.estimate.ringdown.types import FitOptions, FitStatus, ProbeLine, RingdownFit, failure, parameter_std
from mows.estimate.ringdown.window import COIL_OFF_SKIP_S, combine_channels, usable_window

__all__ = [
    "COIL_OFF_SKIP_S",
    "DETERMINED_SIGMAS",
    "RIVAL_CHI2",
    "FitOptions",
    "FitStatus",
    "ProbeLine",
    "RingdownFit",
    "combine_channels",
    "cramer_rao_frequency_hz",
    "cramer_rao_hz",
    "failure",
    "fit_ringdown",
    "fit_ringdowns",
    "fit_tuning",
    "parameter_std",
    "swing_from_signal_rad",
    "starting_point",
    "usable_window",
    "wrapped_rad",
]
