"""The viz core without ROS: the curves from a result's numbers, the arrows' values, lengths and
σ, the mount's frames, and every channel's bytes."""

import json
import math

import numpy as np
import pytest

from foxglove_protobuf import decode, descriptors
from mows.device.recording import bags
from mows.viz import channels
from mows.viz.curves import RingdownModel, stride, sweep_curve_hz
from mows.viz.mount import Mount
from mows.viz.scene import ProbeField, field_magnitude, principal_gradients, probe_arrows
from mows.viz.view import RAW, RINGDOWN, SCENE, SWEEP, View, ViewSettings
from viz.session import SWEEP as SWEPT
from viz.session import recorded_session, sweep_message

MOUNT = "mows_bringup/urdf/mows_probe_mount.urdf"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return recorded_session(tmp_path_factory.mktemp("viz"))


def shown_of(bag, view, topics=None):
    from mows.viz.recording import view_messages

    return [s for s in view_messages(bag, view) if topics is None or s.topic in topics]


def test_ringdown_model_from_the_fit_leaves_only_the_noise(session):
    bag, fits = session
    plots = [s.content for s in shown_of(bag, View(), {RINGDOWN})]
    assert [p.cycle_id for p in plots] == [1, 2]
    for plot, fit in zip(plots, fits):
        assert plot.frequency_hz == fit.frequency_hz
        data, residual = np.array(plot.data_t), np.array(plot.residual_t)
        assert np.allclose(residual, data - np.array(plot.model_t))
        # The model of the fit's own numbers: what is left is the fit's noise, not the ring-down.
        assert np.sqrt(np.mean(residual**2)) < 1.3 * fit.noise_std_t
        assert np.std(data) > 10 * np.sqrt(np.mean(residual**2))
        assert len(plot.t_s) <= ViewSettings().max_points and plot.t_s[-1] < fit.duration_s


def test_a_wrong_frequency_leaves_the_ring_down_in_the_residual(session):
    bag, fits = session
    view = View()
    records = list(bags.read_bag(bag, ["/mows/raw", "/mows/ringdown"]))
    fit_msg = next(r.message for r in records if r.topic == "/mows/ringdown")
    for record in records:
        if record.topic == "/mows/raw":
            view.on_raw(record.message)
        elif record.message is fit_msg:
            fit_msg.frequency_hz += 1.0
            (shown,) = view.on_ringdown(fit_msg, record.timestamp_ns)
            break
    assert np.sqrt(np.mean(np.array(shown.content.residual_t) ** 2)) > 5 * fits[0].noise_std_t


def test_model_needs_every_number_but_the_swing():
    assert not RingdownModel(math.nan, 1.8, 0.1, 0.0, 1e-6, 0.0, (0j, 1 + 0j)).drawable
    assert not RingdownModel(112.0, 1.8, 0.1, 0.0, 1e-6, 0.0, ()).drawable
    assert RingdownModel(112.0, 1.8, math.nan, 0.0, 1e-6, 0.0, (0j, 1 + 0j)).drawable


def test_an_undetermined_swing_is_drawn_by_the_nearest_of_its_fits():
    truth = RingdownModel(100.0, 2.0, 0.2, 0.5, 2e-6, 1e-7, (0.1 + 0j, 1 + 0j, 0.3 + 0.2j))
    t = np.arange(2000) / 4000.0
    data = truth.signal_t(t)
    unknown = RingdownModel(100.0, 2.0, math.nan, 0.5, 5e-6, 0.0, truth.pickup)
    drawn = unknown.completed(t, data)
    assert np.max(np.abs(drawn.signal_t(t) - data)) < 0.02 * np.ptp(data)
    assert unknown.completed(t, data).amplitude_rad == drawn.amplitude_rad
    assert truth.completed(t, data) is truth  # a known swing is the fit's


def test_the_paper_pickup_is_the_linear_signal():
    # C = (0, 1): g(x) = Re e^(ix) = cos x; with x small, κ·cos x ≈ κ(1 − x²/2).
    model = RingdownModel(100.0, 2.0, 0.3, 0.5, 2e-6, 1e-7, (0j, 1 + 0j))
    t = np.linspace(0, 0.1, 50)
    x = 0.3 * np.exp(-2.0 * t) * np.cos(2 * np.pi * 100.0 * t + 0.5)
    assert np.allclose(model.signal_t(t), 2e-6 * np.cos(x) + 1e-7, rtol=0, atol=1e-18)


def test_sweep_curve_is_the_harmonic_series():
    theta = np.array([0.0, math.pi / 2, math.pi])
    assert np.allclose(sweep_curve_hz([1.0, 2.0, 3.0], [0.0, 0.0, math.pi / 2], theta), [3.0, 1.0, -1.0])


def test_stride_keeps_at_most_the_points_asked():
    assert stride(10_000, 2000) == 5 and stride(10_001, 2000) == 6 and stride(10, 2000) == 1
    with pytest.raises(ValueError, match="max_points = 0"):
        stride(10, 0)


def test_field_magnitude_and_its_sigma():
    b, sigma = field_magnitude([3e-5, 4e-5], np.diag([1e-12, 4e-12]))
    assert b == pytest.approx(5e-5)
    assert sigma == pytest.approx(math.sqrt(0.36 * 1e-12 + 0.64 * 4e-12))


def test_principal_gradients_and_their_sigma_by_perturbation():
    g, covariance = np.array([2e-4, 5e-5, -1e-4]), np.diag([1e-12, 4e-12, 9e-12])
    principals = principal_gradients(g, covariance)
    values = np.linalg.eigvalsh([[g[0], g[1]], [g[1], g[2]]])
    assert sorted(p.value_t_per_m for p in principals) == pytest.approx(sorted(values))
    # σ of each eigenvalue against a numerical Jacobian of eigvalsh.
    step = 1e-9
    jacobian = np.empty((2, 3))
    for k in range(3):
        dg = np.zeros(3)
        dg[k] = step
        up, down = g + dg, g - dg
        jacobian[:, k] = (
            np.linalg.eigvalsh([[up[0], up[1]], [up[1], up[2]]])
            - np.linalg.eigvalsh([[down[0], down[1]], [down[1], down[2]]])
        ) / (2 * step)
    expected = np.sqrt(np.einsum("ik,kl,il->i", jacobian, covariance, jacobian))
    by_value = sorted(principals, key=lambda p: p.value_t_per_m)
    assert [p.std_t_per_m for p in by_value] == pytest.approx(list(expected), rel=1e-5)
    for p in principals:  # each direction is the eigenvector of its value
        matrix = np.array([[g[0], g[1]], [g[1], g[2]]])
        assert matrix @ p.direction == pytest.approx(p.value_t_per_m * p.direction, abs=1e-12)


def test_the_largest_b_and_a_significant_gradient_have_the_asked_length_and_labels_say_value_and_sigma():
    msg = sweep_message(1.0)
    near = ProbeField.of(msg, "plane")
    far = ProbeField(1, "plane", np.array([0.0, 0.05, 0.0]), near.field_t / 2, near.field_covariance_t2,
                     near.gradient_t_per_m / 4, near.gradient_covariance)  # fmt: skip
    arrows = probe_arrows([near, far], arrow_length_m=0.1)
    b0, b1 = arrows[0][0], arrows[1][0]
    assert (b0.length_m, b1.length_m) == pytest.approx((0.1, 0.05))
    magnitude, sigma = field_magnitude(near.field_t, near.field_covariance_t2)
    assert b0.label == f"B {magnitude * 1e6:.4g} ± {sigma * 1e6:.2g} µT"
    assert b0.direction[:2] == pytest.approx(near.field_t / magnitude)
    # Both probes' gradients are over 5 σ: full length, whatever their size.
    far_principals = principal_gradients(far.gradient_t_per_m, far.gradient_covariance)
    assert min(abs(p.value_t_per_m) / p.std_t_per_m for p in far_principals) > 5
    assert [a.length_m for probe in (0, 1) for a in arrows[probe][1:]] == pytest.approx([0.1] * 8)
    assert np.allclose(arrows[1][0].tail_m, [0.0, 0.05, 0.0])


@pytest.mark.parametrize("value_mt_per_m, std_mt_per_m", [(-0.013, 0.032), (0.05, 0.02), (0.2, 0.02), (0.0, 0.0)])
def test_a_gradient_arrow_is_as_long_as_its_significance(value_mt_per_m, std_mt_per_m):
    # Gxx alone: λ = Gxx along x with σ_λ = σ(Gxx); next to it a probe with a large, sure gradient.
    msg = sweep_message(1.0)
    sure = ProbeField.of(msg, "plane")
    covariance = np.diag([(std_mt_per_m * 1e-3) ** 2, 0.0, 0.0])
    faint = ProbeField(1, "plane", np.array([0.0, 0.05, 0.0]), sure.field_t, sure.field_covariance_t2,
                       np.array([value_mt_per_m * 1e-3, 0.0, 0.0]), covariance)  # fmt: skip
    arrows = probe_arrows([sure, faint], arrow_length_m=0.1)
    first = arrows[1][1]
    z = abs(value_mt_per_m) / std_mt_per_m if std_mt_per_m else 0.0
    assert first.length_m == pytest.approx(0.1 * min(z, 5.0) / 5.0)
    assert first.label.startswith(f"G1 {value_mt_per_m:+.3g} ± {std_mt_per_m:.2g} mT/m")
    assert [a.length_m for a in arrows[0][1:]] == pytest.approx([0.1] * 4)


def test_a_gradient_of_unknown_sigma_draws_no_arrow_but_says_so():
    msg = sweep_message(1.0)
    sure = ProbeField.of(msg, "plane")
    unknown = ProbeField(0, "plane", sure.position_m, sure.field_t, sure.field_covariance_t2,
                         sure.gradient_t_per_m, np.full((3, 3), np.nan))  # fmt: skip
    (arrows,) = probe_arrows([unknown]).values()
    assert [a.length_m for a in arrows[1:]] == [0.0] * 4
    assert "± nan" in arrows[1].label


def test_mount_frames_turn_the_probe_by_the_stage_angle():
    with open(MOUNT) as text:
        mount = Mount(text.read())
    frames = {f.child: f for f in mount.transforms({"mows_stage": 0.7})}
    assert frames["mows_probe"].rotation == pytest.approx([0, 0, math.sin(0.35), math.cos(0.35)])
    near = frames["fluxgate_near"]
    assert near.parent == "mows_magnetometer" and near.translation_m == pytest.approx([0.06, 0, 0])
    assert near.rotation == pytest.approx([0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)])


def test_a_mimic_joint_follows_its_leader():
    urdf = """<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="lead" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>
      <joint name="follow" type="continuous"><parent link="a"/><child link="c"/><axis xyz="0 0 1"/>
        <mimic joint="lead" multiplier="2" offset="0.1"/></joint></robot>"""
    frames = {f.child: f for f in Mount(urdf).transforms({"lead": 0.3})}
    assert frames["c"].rotation == pytest.approx([0, 0, math.sin(0.35), math.cos(0.35)])


def test_every_channel_encodes_with_its_schema(session):
    bag, _ = session
    with open(MOUNT) as text:
        shown = shown_of(bag, View(mount=Mount(text.read())))
    topics = {s.topic for s in shown}
    assert topics == set(channels.TOPICS)
    for item in shown:
        schema = channels.schema(item.topic)
        data = channels.payload(item)
        if schema.message_encoding == "json":
            message = json.loads(data)
            declared = json.loads(schema.data)["properties"]
            assert set(message) == set(declared), item.topic
        else:
            decoded = decode(data, schema.name, descriptors(schema.data))
            assert decoded, item.topic
    raw = [s.content for s in shown if s.topic == RAW]
    assert raw and all(r.difference_t == pytest.approx(r.near_t - r.far_t) for r in raw[:100])


def test_scene_arrows_in_protobuf_carry_the_sweep(session):
    bag, _ = session
    (scene,) = [s for s in shown_of(bag, View(), {SCENE})]
    schema = channels.schema(SCENE)
    update = decode(channels.payload(scene), schema.name, descriptors(schema.data))
    (entity,) = update["entities"]
    assert entity["frame_id"] == "mows_rotation_plane" and entity["id"] == "probe_0/field"
    b_arrow = entity["arrows"][0]
    length = b_arrow["shaft_length"] + b_arrow["head_length"]
    assert length == pytest.approx(ViewSettings().arrow_length_m)
    # The arrow points along +x turned by its orientation: B's direction in the plane.
    q = b_arrow["pose"]["orientation"]
    turned = np.array(
        [
            1 - 2 * (q.get("y", 0) ** 2 + q.get("z", 0) ** 2),
            2 * (q.get("x", 0) * q.get("y", 0) + q.get("z", 0) * q.get("w", 0)),
        ]
    )
    assert turned == pytest.approx(SWEPT["field_t"] / np.hypot(*SWEPT["field_t"]))
    magnitude, sigma = field_magnitude(SWEPT["field_t"], SWEPT["field_covariance_t2"].reshape(2, 2))
    assert entity["texts"][0]["text"] == f"B {magnitude * 1e6:.4g} ± {sigma * 1e6:.2g} µT"


def test_sweep_plot_has_error_bars_and_the_curve(session):
    bag, _ = session
    (plot,) = [s.content for s in shown_of(bag, View(), {SWEEP})]
    msg = sweep_message(0.0)
    assert plot.theta0_deg == pytest.approx(np.degrees(msg.theta0_rad))
    assert np.array(plot.upper_hz) - np.array(plot.lower_hz) == pytest.approx(2 * msg.frequency_shift_std_hz)
    at_points = sweep_curve_hz(msg.harmonic_amplitude_hz, msg.harmonic_phase_rad, msg.theta0_rad)
    assert at_points == pytest.approx(msg.frequency_shift_hz)
    assert plot.curve_shift_hz[0] == pytest.approx(at_points[0]) and len(plot.curve_theta0_deg) == 181


def test_lab_history_grows_by_sweep_and_replaces_a_repeated_one():
    from viz.session import model_report_message

    view = View()
    view.on_model_report(model_report_message(1.0, 1, 0.03), 1)
    view.on_model_report(model_report_message(2.0, 2, 0.02), 2)
    (shown,) = view.on_model_report(model_report_message(3.0, 2, 0.01), 3)
    assert shown.content.sweep_id == [1, 2] and shown.content.cv_rms_hz == [0.03, 0.01]


def test_settings_refuse_by_name():
    with pytest.raises(ValueError, match="raw_rate_hz = 0"):
        ViewSettings(raw_rate_hz=0)
    with pytest.raises(ValueError, match="topic = '/nothing'"):
        channels.schema("/nothing")


def test_a_fit_that_comes_before_its_samples_is_drawn_once_they_come(session):
    # Live, a fit may overtake the last blocks of its window: every fit of the bag is still drawn,
    # over all of its samples.
    from mows.viz.recording import FEEDS

    bag, fits = session
    records = list(bags.read_bag(bag, FEEDS))
    early = []
    for fit in (r for r in records if r.topic == "/mows/ringdown"):
        records.remove(fit)
        start = fit.message.header.stamp.sec * 10**9 + fit.message.header.stamp.nanosec
        # Just after the first block of its window.
        first = next(i for i, r in enumerate(records) if r.topic == "/mows/raw" and _stamp(r.message) >= start)
        records.insert(first + 1, fit)
        early.append(fit)
    view = View()
    plots = [s.content for r in records for s in FEEDS[r.topic](view, r.message, r.timestamp_ns) if s.topic == RINGDOWN]
    assert [p.cycle_id for p in plots] == [f.message.cycle_id for f in early] == [1, 2]
    for plot in plots:
        assert np.all(np.isfinite(plot.data_t)) and len(plot.data_t) >= ViewSettings().max_points // 2


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
