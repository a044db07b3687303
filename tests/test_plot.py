"""Plots, drawings and animations: what was drawn (artists, labels, units, frames), checked
against the run's own arrays and the four-bar / slider-crank closed forms."""

import jax

jax.config.update("jax_enable_x64", True)

import dataclasses  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from jaxmech import Status  # noqa: E402
from jaxmech.viz import plot  # noqa: E402
from jaxmech.scenes import get_scene, run_scene  # noqa: E402

N = 101
POS_TOL = 1e-12  # m or rad: drawn coordinates are the run's values, copied
TOGGLE_TOL = 2e-3  # rad of crank: linear interpolation of dq/du over a 0.063 rad step


@pytest.fixture(scope="module")
def fourbar():
    return run_scene(get_scene("fourbar"), points=N)


@pytest.fixture(scope="module")
def slider():
    return run_scene(get_scene("slider_crank"), points=N)


def _by_gid(ax, gid):
    return [a for a in ax.get_children() if a.get_gid() == gid]


# ----------------------------------------------------------------------- curves
def test_coordinates_one_axes_per_unit(fourbar, slider):
    fig = plot.plot_coordinates(fourbar)
    (ax,) = fig.axes
    assert ax.get_xlabel() == "theta2 [deg]"  # angles are read in degrees; the CSV stays SI
    assert ax.get_ylabel() == "position [deg]"
    lines = ax.get_lines()
    assert [ln.get_label() for ln in lines] == ["theta3", "theta4"]
    np.testing.assert_allclose(lines[1].get_ydata(), np.asarray(fourbar.motion.q[:, 1]) * 180 / math.pi, rtol=1e-15)
    np.testing.assert_allclose(lines[1].get_xdata(), np.asarray(fourbar.motion.u[:, 0]) * 180 / math.pi, rtol=1e-15)
    assert lines[1].get_xdata()[-1] == pytest.approx(360.0, rel=1e-15)  # one crank turn

    fig = plot.plot_coordinates(slider)  # an angle and a length: two scales
    assert [ax.get_ylabel() for ax in fig.axes] == ["position [deg]", "position [m]"]
    assert [len(ax.get_lines()) for ax in fig.axes] == [1, 1]


def test_velocities_accelerations_units_and_time_axis(slider):
    fig = plot.plot_velocities(slider, against="time")
    assert [ax.get_ylabel() for ax in fig.axes] == ["velocity [deg/s]", "velocity [m/s]"]
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_ydata(), np.degrees(np.asarray(slider.motion.q_dot[:, 0])), rtol=1e-15)
    assert fig.axes[-1].get_xlabel() == "t [s]"
    assert fig.axes[1].get_lines()[0].get_label() == "x_dot"
    np.testing.assert_array_equal(fig.axes[1].get_lines()[0].get_ydata(), np.asarray(slider.motion.q_dot[:, 1]))

    fig = plot.plot_accelerations(slider, names=["x"])
    (ax,) = fig.axes
    assert ax.get_ylabel() == "acceleration [m/s^2]"
    assert ax.get_lines()[0].get_label() == "x_ddot"
    with pytest.raises(ValueError, match="unknown coordinate 'y'"):
        plot.plot_coordinates(slider, names=["y"])
    with pytest.raises(ValueError, match="against"):
        plot.plot_coordinates(slider, against="crank")


def test_outputs(fourbar, slider):
    fig = plot.plot_outputs(fourbar)
    (ax,) = fig.axes
    assert ax.get_ylabel() == "transmission_angle [deg]"
    assert ax.get_xlabel() == "theta2 [deg]"
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), np.degrees(np.asarray(fourbar.outputs["transmission_angle"][0])), rtol=1e-15)
    with pytest.raises(ValueError, match="no outputs"):
        plot.plot_outputs(slider)


# ----------------------------------------------------------------------- transmission, MA, toggles
def _fourbar_p(result):
    return (result.params[k] for k in "abcd")


def test_transmission_angle_is_coupler_rocker_angle(fourbar):
    th3, th4 = np.asarray(fourbar.motion.q).T
    mu = plot.transmission_angle(fourbar)  # the scene's spec: ("A", "B", "O4")
    np.testing.assert_allclose(mu, np.arccos(np.cos(th4 - th3)), atol=1e-12)


def test_mechanical_advantage_closed_form(fourbar, slider):
    a, b, c, d = _fourbar_p(fourbar)
    th2 = np.asarray(fourbar.motion.u[:, 0])
    th3, th4 = np.asarray(fourbar.motion.q).T
    ratio = a * np.sin(th2 - th3) / (c * np.sin(th4 - th3))  # omega4 / omega2
    ma, unit = plot.mechanical_advantage(fourbar)
    assert unit == "-"
    np.testing.assert_allclose(ma, 1 / np.abs(ratio), rtol=1e-9)

    ma, unit = plot.mechanical_advantage(slider)  # crank torque to slider force
    assert unit == "rad/m"
    ma_b, unit_b = plot.mechanical_advantage(slider, output="B")  # the slider pin as a point
    assert unit_b == "rad/m"
    np.testing.assert_allclose(ma_b, ma, rtol=1e-9)
    with pytest.raises(ValueError, match="unknown output 'Q'"):
        plot.mechanical_advantage(slider, output="Q")


def test_fourbar_toggles_at_rocker_limits(fourbar):
    a, b, c, d = _fourbar_p(fourbar)
    # Crank and coupler in line: |O2 B| = a + b (extended) or b - a (folded, A opposite B).
    ext = math.acos((d * d + (a + b) ** 2 - c * c) / (2 * d * (a + b)))
    fold = math.pi + math.acos((d * d + (b - a) ** 2 - c * c) / (2 * d * (b - a)))
    toggles = plot.find_toggles(fourbar)
    assert [t.kind for t in toggles] == ["limit", "limit"]
    np.testing.assert_allclose([t.u for t in toggles], [ext, fold], atol=TOGGLE_TOL)
    # The transmission angle at the crank pivot (crank against O2-B) is 0 and 180 deg there.
    toggles = plot.find_toggles(fourbar, transmission=("A", "O2", "B"), angle_tol=math.radians(3))
    kinds = [t.kind for t in toggles]
    assert kinds.count("transmission") == 2 and kinds.count("limit") == 2
    for t in toggles:
        assert abs(t.u - (ext if t.u < 2 else fold)) < 0.04  # nearest sample of a 0.063 rad grid


def test_slider_toggles_at_dead_centres(slider):
    a, b, e = (slider.params[k] for k in "abe")
    toggles = plot.find_toggles(slider)
    expected = [math.asin(e / (a + b)), math.pi + math.asin(e / (b - a))]
    assert [t.kind for t in toggles] == ["limit", "limit"]
    np.testing.assert_allclose([t.u for t in toggles], expected, atol=TOGGLE_TOL)


def test_singular_status_and_blowup_are_toggles(fourbar):
    status = np.asarray(fourbar.motion.status).copy()
    status[40] = Status.SINGULAR
    d = np.asarray(fourbar.motion.dq_du).copy()
    d[70, 1, 0] = 1e6  # |dtheta4/dtheta2| unbounded at one sample
    mo = dataclasses.replace(fourbar.motion, status=status, dq_du=d)
    res = dataclasses.replace(fourbar, motion=mo)
    kinds = {t.kind: t.index for t in plot.find_toggles(res)}
    assert kinds["singular"] == 40
    assert kinds["blowup"] == 70


def test_plot_transmission_marks_toggles(fourbar, slider):
    fig = plot.plot_transmission(fourbar)
    assert [ax.get_ylabel() for ax in fig.axes] == ["transmission angle [deg]", "mechanical advantage [-]"]
    assert fig.axes[-1].get_xlabel() == "theta2 [deg]"
    toggles = plot.find_toggles(fourbar)
    for ax in fig.axes:
        marks = _by_gid(ax, "toggle")
        assert len(marks) == 2
        assert marks[0].get_label() == "toggle: limit"
        # marked at the toggles' crank angles, in degrees like the axis
        np.testing.assert_allclose([m.get_xdata()[0] for m in marks], [math.degrees(t.u) for t in toggles], rtol=1e-12)
    mu_deg = fig.axes[0].get_lines()[0].get_ydata()
    np.testing.assert_allclose(mu_deg, np.degrees(plot.transmission_angle(fourbar)))

    fig = plot.plot_transmission(slider)  # no transmission angle defined: MA only
    (ax,) = fig.axes
    assert ax.get_ylabel() == "mechanical advantage [rad/m]"
    assert ax.get_yscale() == "log"


# ----------------------------------------------------------------------- drawing
def test_draw_fourbar_links_at_pose(fourbar):
    i = 30
    ax = plot.draw_mechanism(fourbar, i, labels=True)
    links = _by_gid(ax, "link")
    assert len(links) == 3
    assert len(_by_gid(ax, "ground")) == 2
    assert len(_by_gid(ax, "trace")) == 1
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x [m]", "y [m]")
    a, b, c, d = _fourbar_p(fourbar)
    th2 = float(fourbar.motion.u[i, 0])
    th3, th4 = (float(v) for v in fourbar.motion.q[i])
    A = a * np.exp(1j * th2)
    B = d + c * np.exp(1j * th4)
    crank, coupler, rocker = links
    np.testing.assert_allclose(crank.get_xydata(), [[0, 0], [A.real, A.imag]], atol=POS_TOL)
    np.testing.assert_allclose(coupler.get_xydata(), [[A.real, A.imag], [B.real, B.imag]], atol=POS_TOL)
    np.testing.assert_allclose(rocker.get_xydata(), [[d, 0], [B.real, B.imag]], atol=POS_TOL)
    # Coupler length is b at this pose: the drawing closes the loop.
    assert abs(abs(B - A) - b) < 1e-9
    # The traced coupler midpoint covers the whole stroke.
    assert len(_by_gid(ax, "trace")[0].get_xdata()) == N
    assert {t.get_text() for t in ax.texts} == {"O2", "O4", "A", "B", "P"}
    assert ax.get_title() == f"theta2 = {math.degrees(th2):.4g} deg"


def test_draw_slider_crank_slot_and_dead_centres(slider):
    ax = plot.draw_mechanism(slider, -1)
    assert len(_by_gid(ax, "link")) == 2
    (slot,) = _by_gid(ax, "slot")
    a, b, e = (slider.params[k] for k in "abe")
    np.testing.assert_allclose(slot.get_ydata(), [e, e])  # the line y = e
    x = np.asarray(slider.motion.q[:, 1])
    assert slot.get_xdata()[0] < x.min() and slot.get_xdata()[1] > x.max()


def test_custom_spec_arc_slot_chord_polygon(fourbar):
    c, d = fourbar.params["c"], fourbar.params["d"]
    spec = {
        "links": [("O2", "A")],
        "slots": [{"centre": "O4", "radius": c, "pin": "B"}, {"centre": d + 0j, "radius": 0.5, "angles": (0.0, math.pi)}],
        "chords": [("A", "B")],
        "polygons": [("A", "B", "P")],
        "trace": ["B"],
    }
    ax = plot.draw_mechanism(fourbar, 10, spec=spec)
    arc, half = _by_gid(ax, "slot")
    z = arc.get_xdata() + 1j * arc.get_ydata()
    np.testing.assert_allclose(np.abs(z - d), c, rtol=1e-12)  # the rocker pin's arc about O4
    ang = np.angle(z - d)
    th4 = np.asarray(fourbar.motion.q[:, 1])
    assert ang.min() < th4.min() and ang.max() > th4.max()  # covers the pin's swing
    np.testing.assert_allclose(half.get_ydata().min(), 0.0, atol=1e-12)  # upper half circle
    assert len(_by_gid(ax, "chord")) == 1 and len(_by_gid(ax, "polygon")) == 1
    assert len(_by_gid(ax, "link")) == 1


def test_spec_errors_name_the_problem(fourbar):
    with pytest.raises(ValueError, match="unknown drawing key"):
        plot.draw_mechanism(fourbar, spec={"bars": []})
    with pytest.raises(ValueError, match="unknown point 'Z'"):
        plot.draw_mechanism(fourbar, spec={"links": [("A", "Z")]})
    with pytest.raises(ValueError, match="out of range"):
        plot.draw_mechanism(fourbar, N)


def test_scene_without_drawing_shows_its_points(fourbar):
    res = dataclasses.replace(fourbar, scene=dataclasses.replace(fourbar.scene, drawing=None))
    ax = plot.draw_mechanism(res)
    (pts,) = _by_gid(ax, "point")
    assert len(pts.get_xdata()) == len(fourbar.scene.mechanism.points)
    assert len(_by_gid(ax, "trace")) == len(fourbar.scene.mechanism.points)
    assert not _by_gid(ax, "link")


def test_plot_poses_start_middle_end(fourbar):
    fig = plot.plot_poses(fourbar)
    assert len(fig.axes) == 3
    assert [len(_by_gid(ax, "link")) for ax in fig.axes] == [3, 3, 3]
    u = np.asarray(fourbar.motion.u[:, 0])
    assert [ax.get_title() for ax in fig.axes] == [f"theta2 = {math.degrees(u[i]):.4g} deg" for i in (0, N // 2, N - 1)]


# ----------------------------------------------------------------------- animation and files
def test_animate_gif_and_html(fourbar, tmp_path):
    anim = plot.animate(fourbar, tmp_path / "fb.gif", frames=6, trace=["P", "B"])
    np.testing.assert_array_equal(anim.frame_indices, [0, 20, 40, 60, 80, 100])
    with Image.open(tmp_path / "fb.gif") as im:
        assert im.n_frames == 6
    ax = anim._fig.axes[0]
    assert len(_by_gid(ax, "trace")) == 2  # full paths of P and B ...
    progress = _by_gid(ax, "trace-progress")  # ... and the part traced so far (last frame: all)
    assert len(progress) == 2 and len(progress[0].get_xdata()) == N

    anim = plot.animate(fourbar, tmp_path / "fb.html", frames=3)
    html = (tmp_path / "fb.html").read_text()
    assert "<script" in html and html.count("data:image/png;base64") == 3
    with pytest.raises(ValueError, match=r"\.gif, \.mp4 or \.html"):
        plot.animate(fourbar, tmp_path / "fb.avi")


def test_animate_mp4_leaves_matplotlib_settings(fourbar, tmp_path, monkeypatch):
    """An MP4 through the ``video`` extra's ffmpeg, pointed at for the save only; without any
    ffmpeg, a ``RuntimeError`` naming the extra before anything is drawn."""
    import imageio_ffmpeg
    import matplotlib

    before = matplotlib.rcParams["animation.ffmpeg_path"]
    anim = plot.animate(fourbar, tmp_path / "fb.mp4", frames=4, dpi=40)
    assert matplotlib.rcParams["animation.ffmpeg_path"] == before
    assert len(anim.frame_indices) == 4
    data = (tmp_path / "fb.mp4").read_bytes()
    assert data[4:8] == b"ftyp"
    assert imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "fb.mp4"))[0] == 4

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    monkeypatch.setitem(matplotlib.rcParams, "animation.ffmpeg_path", str(tmp_path / "no-ffmpeg"))
    with pytest.raises(RuntimeError, match=r'pip install "jaxmech\[video\]"'):
        plot.animate(fourbar, tmp_path / "none.mp4", frames=2)
    assert not (tmp_path / "none.mp4").exists()


def test_save_default_plots(fourbar, slider, tmp_path):
    paths = plot.save_default_plots(fourbar, tmp_path)
    names = [p.name for p in paths]
    assert names == [f"fourbar_{k}.png" for k in ("coordinates", "velocities", "accelerations", "outputs", "transmission", "poses")]
    for p in paths:
        with Image.open(p) as im:
            assert im.format == "PNG" and im.size[0] > 300
    names = [p.name for p in plot.save_default_plots(slider, tmp_path)]
    assert "slider_crank_outputs.png" not in names and "slider_crank_poses.png" in names
