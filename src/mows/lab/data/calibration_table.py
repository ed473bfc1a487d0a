"""The calibration table (``mows calibrate TABLE``, ``--table``): a CSV of ring-down fits, one
row a calibration point (:class:`mows.estimate.calibration.constants.CalibrationPoint`) with the
columns ``supply_current_a``, ``theta0_deg``, ``f_hz``, ``f_std_hz``, ``damping_per_s``,
``duration_s``, ``amplitude_deg`` (θmax; ``amplitude_fitted`` 0 where the fit did not determine
it), ``start_offset_s`` and ``gradient_wiring`` (0: the homogeneous wiring, 1: the gradient one),
written and read back, each column checked by name.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping, Sequence

import numpy as np

from mows.estimate.calibration.constants import CalibrationPoint
from mows.lab.data.readers import load_table
from mows.lab.data.table import MeasurementTable, rows_text
from mows.physics.ringdown_average import swing_from_stop_rad
from mows.records.files import read_input
from mows.sweep.calibration.schedule import GRADIENT_WIRING

#: A cantilever's swing is a fraction of a turn: a θmax of half a turn or more is no angle in degrees.
MAX_AMPLITUDE_DEG = 180.0
TABLE_COLUMNS = (
    "supply_current_a",
    "damping_per_s",
    "duration_s",
    "amplitude_deg",
    "start_offset_s",
    "gradient_wiring",
)


def write_points(
    path: str | os.PathLike[str], points: Sequence[CalibrationPoint], field_wiring: str, stop_rad: float
) -> None:
    """The calibration's points as a table. ``amplitude_deg`` is each fit's θmax, or where the
    fit did not determine it the stop less its rest offset (the start swing's rule), flagged 0
    in ``amplitude_fitted`` so that :func:`read_points` reads it back as not measured."""
    fitted = np.array([math.isfinite(p.amplitude_rad) for p in points])
    columns = {
        "theta0_deg": np.degrees([p.theta0_rad for p in points]),
        "f_hz": np.array([p.frequency_hz for p in points]),
        "f_std_hz": np.array([p.frequency_std_hz for p in points]),
        "supply_current_a": np.array([p.supply_current_a for p in points]),
        "damping_per_s": np.array([p.damping_per_s for p in points]),
        "duration_s": np.array([p.duration_s for p in points]),
        "amplitude_deg": np.degrees(_start_amplitudes_rad(points, stop_rad)),
        "amplitude_fitted": fitted.astype(float),
        "start_offset_s": np.array([p.start_offset_s for p in points]),
        "gradient_wiring": np.array([float(p.wiring != field_wiring) for p in points]),
    }
    MeasurementTable(columns, str(path)).to_csv(path)


def _start_amplitudes_rad(points: Sequence[CalibrationPoint], stop_rad: float) -> np.ndarray:
    """Each point's θmax, or where its fit did not determine it the swing released at the stop
    about the fit's rest offset (0 where that is not determined either), decayed to the fit's
    first sample (:func:`mows.physics.ringdown_average.swing_from_stop_rad`): a swing the
    physics allows, never NaN."""
    amplitude = np.array([p.amplitude_rad for p in points], float)
    rest = np.nan_to_num(np.array([p.rest_offset_rad for p in points], float))
    damping = np.array([p.damping_per_s for p in points], float)
    since_release = np.array([p.start_offset_s for p in points], float)
    released = np.nan_to_num(swing_from_stop_rad(stop_rad, rest, damping, since_release))
    return np.where(np.isfinite(amplitude), amplitude, released)


def _table_columns(path: str | os.PathLike[str]) -> Mapping:
    """The table's columns, every calibration column a finite number in every row; a θmax the
    fits did not determine (NaN in ``amplitude_deg``) is read as not measured, as
    :func:`write_points` flags it (``amplitude_fitted`` 0). A file that is no plain CSV of numbers
    is read by the lab's reader, which says what is wrong with it."""
    columns = _numeric_columns(path)
    if columns is None:
        return load_table(path).columns
    amplitude = columns.pop("amplitude_deg", None)  # checked here: NaN is a θmax not measured
    if amplitude is not None:
        flagged = columns.get("amplitude_fitted", np.ones(amplitude.shape))
        columns["amplitude_fitted"] = (np.isfinite(amplitude) & (flagged != 0)).astype(float)
        non_positive = np.flatnonzero(np.isfinite(amplitude) & (amplitude <= 0))
        if len(non_positive):
            raise ValueError(f"column 'amplitude_deg' must be > 0: not so in {rows_text(non_positive)}")
        beyond = np.flatnonzero(np.isfinite(amplitude) & (amplitude >= MAX_AMPLITUDE_DEG))
        if len(beyond):
            raise ValueError(
                f"column 'amplitude_deg' must be below {MAX_AMPLITUDE_DEG:g}° (a swing in degrees): "
                f"not so in {rows_text(beyond)}"
            )
    wiring = columns.get("gradient_wiring", np.zeros(0))
    flags = np.flatnonzero(np.isfinite(wiring) & (wiring != 0) & (wiring != 1))
    if len(flags):
        raise ValueError(
            f"column 'gradient_wiring' is 0 (field pair) or 1 (gradient pair): not so in {rows_text(flags)}"
        )
    for name in ("theta0_deg", "f_hz", "f_std_hz", *TABLE_COLUMNS):
        bad = np.flatnonzero(~np.isfinite(columns[name])) if name in columns else ()
        if len(bad):
            raise ValueError(f"column '{name}' is not a finite number in {rows_text(bad)}")
    checked = dict(load_table(columns).columns)
    if amplitude is not None:
        checked["amplitude_deg"] = amplitude
    return checked


def _numeric_columns(path: str | os.PathLike[str]) -> dict | None:
    """Every column of a CSV of numbers (NaN allowed), or None for any other file."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            values = np.genfromtxt(path, delimiter=",", names=True, encoding="utf-8-sig", invalid_raise=True)
        except (ValueError, IndexError):  # IndexError: an empty file, which numpy does not name
            return None
    names = values.dtype.names or ()
    return {name: np.atleast_1d(values[name]).astype(float) for name in names} or None


def read_points(path: str | os.PathLike[str], field_wiring: str) -> list[CalibrationPoint]:
    """Calibration points from a calibration table (CSV)."""
    c = _table_columns(read_input(path))
    missing = [name for name in TABLE_COLUMNS if name not in c]
    if missing:
        raise ValueError(f"{path}: a calibration table needs the columns {list(TABLE_COLUMNS)}; missing {missing}")
    return [
        CalibrationPoint(
            GRADIENT_WIRING if c["gradient_wiring"][i] else field_wiring,
            float(c["supply_current_a"][i]),
            math.radians(c["theta0_deg"][i]),
            float(c["f_hz"][i]),
            float(c["f_std_hz"][i]),
            math.radians(c["amplitude_deg"][i]) if c.get("amplitude_fitted", np.ones(len(c["f_hz"])))[i] else math.nan,
            float(c["damping_per_s"][i]),
            float(c["duration_s"][i]),
            float(c["start_offset_s"][i]),
        )
        for i in range(len(c["f_hz"]))
    ]
