"""JSON output never carries NaN or infinity (not JSON): a figure the data could not determine
is null, wherever it sits, and every other value is kept."""

import json
import math

import numpy as np

from mows.records.json_numbers import finite_or_none


def test_non_finite_floats_become_null_at_any_depth_and_the_rest_is_kept():
    figures = {
        "nan": math.nan,
        "inf": math.inf,
        "numpy": np.float64(-np.inf),
        "kept": [1.5, np.float32(0.25), 3, True, "text", None],
        "nested": {"pair": (math.nan, 2.0)},
    }
    out = finite_or_none(figures)
    assert json.loads(json.dumps(out, allow_nan=False)) == {
        "nan": None,
        "inf": None,
        "numpy": None,
        "kept": [1.5, 0.25, 3, True, "text", None],
        "nested": {"pair": [None, 2.0]},
    }
    assert type(out["kept"][1]) is float and out["kept"][3] is True


def test_a_single_number_passes_or_becomes_null():
    assert finite_or_none(np.float64(2.5)) == 2.5 and finite_or_none(math.nan) is None
