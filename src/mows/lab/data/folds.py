"""Cross-validation folds: rows held out a configuration at a time.

An effect that describes physics predicts rows measured in a configuration the fit did not
see; one that only absorbs the structure of a few rows does not. So the lab holds out rows by
the configuration they share, the first of these the table has:

1. **sweeps** (``sweep`` with at least two values): whole sweeps, sweep k (in order of its first
   row, the table's time order) in fold k mod K, so that every fold spans the table's time;
2. **current steps** (``coil_current_a`` with 2 … ``MAX_STEPS`` distinct values): whole steps,
   dealt in order of current, so that a fold holds currents from across the range;
3. **temperature spans** (``temperature_k`` varying): K spans of consecutive temperature with
   equal numbers of rows, so that a fold holds out a span the others bracket or extrapolate to;
4. otherwise K interleaved folds of rows.

K = ``CV_FOLDS``, fewer when there are fewer groups (leave one group out).
"""

from __future__ import annotations

import numpy as np

from mows.lab.data.table import MeasurementTable

CV_FOLDS = 10
MAX_STEPS = 50  # more distinct currents than this are a continuous covariate, not steps


def cv_folds(table: MeasurementTable) -> list[np.ndarray]:
    """Row indices of each fold (module docstring)."""
    folds, _ = folds_and_grouping(table)
    return folds


def folds_and_grouping(table: MeasurementTable) -> tuple[list[np.ndarray], str]:
    """(folds, what a fold holds out, in words)."""
    sweeps = table.sweep_ids
    if len(np.unique(sweeps)) > 1:
        return _dealt(_rank_by_first_row(sweeps)), "whole sweeps"
    if table.has("coil_current_a"):
        currents = table.columns["coil_current_a"]
        distinct, inverse = np.unique(currents, return_inverse=True)
        if 1 < len(distinct) <= MAX_STEPS:
            return _dealt(inverse.ravel()), "whole current steps"
    if table.has("temperature_k") and np.ptp(table.columns["temperature_k"]) > 0:
        order = np.argsort(table.columns["temperature_k"], kind="stable")
        span = np.empty(len(table), int)
        span[order] = np.arange(len(table)) * min(CV_FOLDS, len(table)) // len(table)
        return [np.flatnonzero(span == k) for k in range(span.max() + 1)], "spans of temperature"
    count = min(CV_FOLDS, len(table))
    return [np.arange(i, len(table), count) for i in range(count)], "interleaved rows"


def _rank_by_first_row(labels: np.ndarray) -> np.ndarray:
    """Each row's group, numbered in the order of the groups' first rows."""
    unique, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(unique), int)
    rank[np.argsort(first, kind="stable")] = np.arange(len(unique))
    return rank[inverse.ravel()]


def _dealt(group: np.ndarray) -> list[np.ndarray]:
    """Groups numbered 0 … G−1 dealt to min(K, G) folds, group g in fold g mod K."""
    fold = group % CV_FOLDS
    return [np.flatnonzero(fold == k) for k in range(min(CV_FOLDS, int(group.max()) + 1))]
