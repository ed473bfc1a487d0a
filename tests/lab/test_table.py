"""Measurement tables: CSV validation with errors that name the column and row, probe-frame
quantities, covariates, and bags of RingdownFit messages with a reference."""

import math

import numpy as np
import pytest

from mows.device.recording import bags
from mows.lab import MissingColumnError, TableError, from_bag, load_table, read_csv
from recorded_bags import ringdown_fit_message

HEADER = "theta0_deg,f_hz,f_std_hz,ref_bx_t,ref_by_t,ref_gxx_t_per_m,ref_gxy_t_per_m,ref_gyy_t_per_m,humidity\n"


def write(tmp_path, text, name="t.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_table_reads_with_frames_and_covariates(tmp_path):
    path = write(
        tmp_path, HEADER + "0,112.5,0.001,1e-5,2e-5,1e-3,2e-3,-4e-3,40\n90,112.6,0.001,1e-5,2e-5,1e-3,2e-3,-4e-3,41\n"
    )
    table = read_csv(path)
    assert len(table) == 2 and table.humidity.tolist() == [40.0, 41.0]
    np.testing.assert_allclose(table.gradient_t_per_m[0], [[1e-3, 2e-3, 0], [2e-3, -4e-3, 0], [0, 0, 3e-3]])
    covariates = table.covariates()
    # At θ0 = 90° the probe axis is +y: Bx' = By, By' = −Bx; G = Gx'x' = Gyy.
    np.testing.assert_allclose(covariates["b_along_t"], [1e-5, 2e-5])
    np.testing.assert_allclose(covariates["b_perp_t"], [2e-5, -1e-5])
    np.testing.assert_allclose(covariates["g_t_per_m"], [1e-3, -4e-3])
    assert "humidity" in covariates and "f_hz" not in covariates
    assert any("ref_bz_t" in note for note in table.notes)


@pytest.mark.parametrize(
    "text, words",
    [
        ("theta0_deg,f_hz\n0,112\n", ["f_std_hz"]),
        ("theta0_deg,f_hz,f_std_hz\n0,112,0.001\n10,abc,0.001\n", ["f_hz", "'abc'", "row 2"]),
        ("theta0_deg,f_hz,f_std_hz\n0,112,0.001\n10,nan,0.001\n", ["f_hz", "NaN", "row 2"]),
        ("theta0_deg,f_hz,f_std_hz\n0,112,0\n", ["f_std_hz", "> 0", "row 1"]),
        ("theta0_deg,f_hz,f_std_hz,ref_bx_t\n0,112,0.001,1e-6\n", ["ref_bx_t", "ref_by_t"]),
        ("theta0_deg,f_hz,f_std_hz\n0,112\n", ["row 1", "3 cells"]),
        ("theta0_deg,f_hz,f_std_hz\n", ["no rows"]),
    ],
)
def test_bad_tables_name_the_column_and_row(tmp_path, text, words):
    with pytest.raises(TableError) as error:
        read_csv(write(tmp_path, text))
    for word in words:
        assert word in str(error.value)


def test_invalid_rows_can_be_dropped_and_text_columns_are_ignored(tmp_path):
    path = write(tmp_path, "theta0_deg,f_hz,f_std_hz,operator\n0,112,0.001,ann\n10,,0.001,bob\n20,113,0.001,ann\n")
    table = read_csv(path, drop_invalid=True)
    assert table.theta0_deg.tolist() == [0.0, 20.0]
    assert any("operator" in note for note in table.notes) and any("row 2" in note for note in table.notes)
    with pytest.raises(MissingColumnError, match="coil_current_a"):
        _ = table.coil_current_a


def test_a_covariate_with_nan_cells_is_ignored_not_the_table(tmp_path):
    path = write(tmp_path, "theta0_deg,f_hz,f_std_hz,snr_db\n0,112,0.001,40\n10,112.1,0.001,nan\n")
    for drop_invalid in (False, True):
        table = read_csv(path, drop_invalid=drop_invalid)
        assert len(table) == 2 and not table.has("snr_db")
        assert any("snr_db" in note and "row 2" in note for note in table.notes)


def test_a_bag_of_ringdown_fits_with_a_magnetometer_or_a_source_reference(tmp_path):
    store = bags.typestore()
    types = store.types

    def header(seconds):
        return types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=seconds, nanosec=0), frame_id="probe"
        )

    def ringdown(seconds, theta0, status=0):
        return ringdown_fit_message(seconds, theta0, 112.5 + theta0, status)

    def field(seconds, bx):
        vector = types["geometry_msgs/msg/Vector3"](x=bx, y=2e-6, z=-4e-5)
        return types["sensor_msgs/msg/MagneticField"](
            header=header(seconds), magnetic_field=vector, magnetic_field_covariance=np.zeros(9)
        )

    messages = [
        bags.BagMessage("/mows/ringdown", "mows_msgs/msg/RingdownFit", 10**9 * s, ringdown(s, 0.1 * s))
        for s in (10, 20, 30)
    ]
    messages.append(bags.BagMessage("/mows/ringdown", "mows_msgs/msg/RingdownFit", 35 * 10**9, ringdown(35, 0.0, 3)))
    messages += [
        bags.BagMessage("/ref/field", "sensor_msgs/msg/MagneticField", 10**9 * s, field(s, 1e-6 * s))
        for s in (9, 21, 40)
    ]
    bags.write_bag(tmp_path / "bag", sorted(messages, key=lambda m: m.timestamp_ns))

    table = from_bag(tmp_path / "bag", reference="/ref/field")
    assert len(table) == 3 and table.t_s.tolist() == [0.0, 10.0, 20.0]
    np.testing.assert_allclose(table.ref_bx_t, [9e-6, 21e-6, 21e-6])  # nearest in time
    np.testing.assert_allclose(table.amplitude_deg, math.degrees(0.4))
    assert any("status is not OK" in note for note in table.notes)

    sourced = load_table(tmp_path / "bag", reference={"type": "uniform", "field_t": [1e-6, 2e-6, 3e-6]})
    np.testing.assert_allclose(sourced.field_t[0], [1e-6, 2e-6, 3e-6])
    assert sourced.has("ref_gxx_t_per_m")
    with pytest.raises(TableError, match="MagneticField"):
        from_bag(tmp_path / "bag", reference="/missing")
