"""The panels as pictures (``mows viz BAG --figures DIR``, :mod:`mows.viz.figures`): every panel of a
recorded session drawn as a small PNG, and what each picture draws, read back from its plot, is
the View's channel content for that panel."""

import numpy as np
import pytest

from mows.cli.main import main
from mows.viz.figures import DRAWINGS, Panels, draw
from mows.viz.recording import view_messages
from mows.viz.view import EXCITATION, LAB, RINGDOWN, SCENE, SWEEP, View
from viz.session import LAB_ERRORS_HZ, recorded_session

PNG = b"\x89PNG\r\n\x1a\n"
MAX_BYTES = 150_000  # docs/images: small


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return recorded_session(tmp_path_factory.mktemp("figures"))


@pytest.fixture(scope="module")
def shown(session):
    bag, _ = session
    return list(view_messages(bag, View()))


def latest(shown, topic):
    return [s.content for s in shown if s.topic == topic][-1]


def test_mows_viz_figures_writes_one_small_png_per_panel(session, tmp_path, capsys):
    bag, _ = session
    assert main(["viz", str(bag), "--figures", str(tmp_path / "images")]) == 0
    printed = capsys.readouterr().out
    for name in DRAWINGS:
        path = tmp_path / "images" / f"{name}.png"
        assert f"wrote {path}" in printed
        data = path.read_bytes()
        assert data[:8] == PNG and 10_000 < len(data) <= MAX_BYTES, (name, len(data))
    assert not (bag.parent / f"{bag.name}.view.mcap").exists()  # the pictures instead of the MCAP file
    assert main(["viz", str(bag), "--figures", str(tmp_path / "images")]) == 2  # never over them without --force
    assert main(["viz", str(bag), "--figures", str(tmp_path / "images"), "--force"]) == 0
    assert main(["viz", str(bag), "--figures", str(tmp_path), "-o", str(tmp_path / "x.mcap")]) == 2


def test_the_ringdown_picture_draws_the_channel_s_samples_model_and_residual(shown):
    plot = latest(shown, RINGDOWN)
    drawn = draw(Panels.of(shown), "ringdown").data
    for name in ("t_s", "data_t", "model_t", "residual_t"):
        np.testing.assert_array_equal(drawn[name], getattr(plot, name), err_msg=name)


def test_the_sweep_picture_draws_the_points_their_error_bars_and_the_curve(shown):
    plot = latest(shown, SWEEP)
    drawn = draw(Panels.of(shown), "sweep").data
    for name in ("theta0_deg", "frequency_shift_hz", "curve_theta0_deg", "curve_shift_hz"):
        np.testing.assert_array_equal(drawn[name], getattr(plot, name), err_msg=name)
    for name in ("lower_hz", "upper_hz"):  # the bars' ends, from the bars drawn
        np.testing.assert_allclose(drawn[name], getattr(plot, name), rtol=0, atol=1e-12, err_msg=name)


def test_the_lab_picture_draws_the_error_history(shown):
    history = latest(shown, LAB)
    drawn = draw(Panels.of(shown), "lab").data
    assert drawn["sweep_id"].tolist() == history.sweep_id == [sweep for sweep, _ in LAB_ERRORS_HZ]
    np.testing.assert_array_equal(drawn["cv_rms_hz"], history.cv_rms_hz)
    np.testing.assert_array_equal(drawn["chi2_dof"], history.chi2_dof)


def test_the_excitation_picture_draws_every_state_s_currents_and_the_cap(shown):
    states = [s for s in shown if s.topic == EXCITATION]
    drawn = draw(Panels.of(shown), "excitation").data
    np.testing.assert_array_equal(drawn["coil_current_a"], [s.content.coil_current_a for s in states])
    np.testing.assert_allclose(drawn["time_s"], [(s.log_time_ns - states[0].log_time_ns) / 1e9 for s in states])
    assert drawn["cap_a"].tolist() == [states[-1].content.coil_current_cap_a]
    assert drawn["coil_current_a"].max() > 0  # the session's excitations drive the coils


def test_the_scene_picture_draws_every_arrow_from_its_tail_by_its_length(shown):
    arrows = [arrow for entity in latest(shown, SCENE).values() for arrow in entity]
    drawn = draw(Panels.of(shown), "scene").data
    assert len(arrows) == 5  # B and both ends of the two principal gradients
    np.testing.assert_array_equal(drawn["tail_m"], [a.tail_m for a in arrows])
    np.testing.assert_allclose(drawn["vector_m"], [np.asarray(a.direction) * a.length_m for a in arrows])


def test_a_panel_without_content_is_refused_by_name():
    with pytest.raises(ValueError, match="panel = 'sweep': nothing to draw"):
        draw(Panels(), "sweep")
