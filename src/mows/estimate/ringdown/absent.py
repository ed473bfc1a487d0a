"""Probes of a window whose line is not in the data: a probe that did not ring (no magnet, its
excitation refused) leaves its tone free to fit noise or to share a neighbour's line, at an OK
status. :func:`absent_tone` finds the tone the coarse fit does without (its removal raises χ²
by less than ABSENT_CHI2); :func:`own_lines` refuses a fitted line nearer another probe's
expected frequency than its own. Neither ever reports a number for a probe that is not there.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from mows.estimate.ringdown.problem import Evaluation, RingdownProblem, finite_cost, variable_projection
from mows.estimate.ringdown.summary import known_of
from mows.estimate.ringdown.types import FitOptions, FitStatus, ProbeLine, RingdownFit, failure

# A tone whose removal raises χ² by less than this (in units of χ²/dof) is not in the data: a
# tone fitted to noise over its band gains ~10 (5 parameters, the best of ~30 resolved
# frequencies); the weakest line the spectral stage detects (×30 over the floor) gains hundreds.
ABSENT_CHI2 = 25.0


def own_lines(fits: list[RingdownFit], lines: Sequence[ProbeLine], options: FitOptions) -> list[RingdownFit]:
    """``fits`` with NO_OSCILLATION for each probe whose fitted line is nearer another probe's
    expected frequency than its own: that is the other's line (its own is not in the data, and
    the fit took the nearest it found), never a number of its own."""
    fits = list(fits)
    for k, (fit, line) in enumerate(zip(fits, lines)):
        if not fit.ok:
            continue
        nearest = min(lines, key=lambda other: abs(other.expected_frequency_hz - fit.frequency_hz))
        if abs(nearest.expected_frequency_hz - fit.frequency_hz) < abs(line.expected_frequency_hz - fit.frequency_hz):
            message = (
                f"no line of probe {line.probe_id} near {line.expected_frequency_hz:.2f} Hz: its tone went to "
                f"{fit.frequency_hz:.2f} Hz, nearer probe {nearest.probe_id}'s {nearest.expected_frequency_hz:.2f} Hz"
            )
            fits[k] = failure(FitStatus.NO_OSCILLATION, message, **known_of(line, options))
    return fits


def absent_tone(
    coarse: RingdownProblem, step: Evaluation, lines: Sequence[ProbeLine], options: FitOptions
) -> tuple[int, str] | None:
    """The tone the data do without, and why, or None: the one whose removal raises the coarse
    optimum's χ² least, where that is less than ABSENT_CHI2 (in units of its χ²/dof). A probe
    that did not ring (no magnet, its excitation refused) leaves its tone free to fit noise or
    to share a neighbour's line, at an OK status; its line is then not in the data, and the
    others are fitted without it."""
    per_tone = coarse.per_tone
    dof = coarse.y.size - step.q.size - step.coef.size
    unit = step.cost / dof if dof > 0 and step.cost > 0 else math.inf
    rises, kept_hz = [], []
    for k in range(len(lines)):
        kept = np.arange(len(lines)) != k
        without = dataclasses.replace(coarse, pickups=coarse.pickups[kept])
        q = np.delete(step.q, np.s_[k * per_tone : (k + 1) * per_tone])
        fitted = variable_projection(without, q, options.max_iterations, tol_chi2=1e-2)[0]
        rises.append((finite_cost(fitted.cost) - step.cost) / unit)
        kept_hz.append(fitted.q[::per_tone])
    k = int(np.argmin(rises))
    if not rises[k] < ABSENT_CHI2:
        return None
    # The lines that are there belong to the probes expected nearest them: the probe none is
    # nearest to is the one absent (the tone dropped may have sat on its neighbour's line).
    expected = np.array([line.expected_frequency_hz for line in lines])
    owners = {int(np.argmin(np.abs(expected - f))) for f in kept_hz[k]}
    unowned = [i for i in range(len(lines)) if i not in owners]
    absent = unowned[0] if len(unowned) == 1 else k
    line = lines[absent]
    return absent, (
        f"no line of probe {line.probe_id} near {line.expected_frequency_hz:.2f} Hz: the fit without it is "
        f"worse by only Δχ² = {max(rises[k], 0.0):.1f} < {ABSENT_CHI2:g}; "
        "the probe did not ring down (absent, or not excited)"
    )
