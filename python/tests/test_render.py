"""Tests of the dofray Python module (run by scripts/python-test.sh)."""

import _thread
import os
import threading

import numpy as np
import pytest

import dofray

W, H = 64, 48


@pytest.fixture(scope="module")
def paper():
    """A small render of the built-in paper scene; its sky is background."""
    return dofray.render("paper", width=W, height=H, f_number=2.8, focus_distance=5.0)


def test_version():
    assert isinstance(dofray.__version__, str) and dofray.__version__


def test_shapes_and_dtypes(paper):
    assert isinstance(paper, dofray.Render)
    assert (paper.width, paper.height) == (W, H)
    assert paper.rgba.shape == (H, W, 4) and paper.rgba.dtype == np.float32
    assert paper.depth.shape == (H, W) and paper.depth.dtype == np.float32
    assert paper.coc.shape == (H, W) and paper.coc.dtype == np.float32
    assert repr(paper) == f"<dofray.Render {W}x{H}>"


def test_rgba_finite_and_opaque(paper):
    assert np.isfinite(paper.rgba).all()
    assert (paper.rgba[..., :3] >= 0).all()
    assert paper.rgba[..., :3].max() > 0
    # Not transparent: alpha is 1 everywhere.
    assert (paper.rgba[..., 3] == 1).all()


def test_depth_inf_only_where_nothing_is_hit():
    r = dofray.render("paper", width=W, height=H, transparent=True)
    hit = np.isfinite(r.depth)
    assert hit.any() and (~hit).any()
    assert (r.depth[hit] > 0).all()
    assert np.isposinf(r.depth[~hit]).all()
    alpha = r.rgba[..., 3]
    # Where the pinhole ray saw the sky, (almost) nothing covers the pixel, and where it hit a
    # surface, (almost) everything does.
    assert alpha[~hit].mean() < 0.1
    assert alpha[hit].mean() > 0.9
    # RGB is premultiplied: the background adds nothing.
    assert (r.rgba[..., :3][alpha == 0] == 0).all()


def test_coc_grows_off_the_focus_plane(paper):
    coc, depth = paper.coc, paper.depth
    assert np.isfinite(coc).all() and (coc >= 0).all()
    hit = np.isfinite(depth)
    near = hit & (np.abs(depth - 5.0) < 0.25)
    far = hit & (depth > 8.0)
    assert near.sum() > 10 and far.sum() > 10
    assert coc[far].mean() > 5 * coc[near].mean()
    # A smaller aperture blurs less.
    small = dofray.render("paper", width=W, height=H, f_number=16, focus_distance=5.0)
    assert small.coc[far].mean() < coc[far].mean()


def test_stats(paper):
    stats = paper.stats
    assert isinstance(stats, dict)
    keys = ("rays", "seconds", "mrays_per_s", "sample_sites", "defocused_sites")
    for key in keys + ("borrowing_sites", "rounds"):
        assert key in stats, key
    rays = stats["rays"]
    assert rays["total"] == rays["primary"] + rays["shadow"] + rays["secondary"]
    assert rays["primary"] >= W * H
    assert stats["seconds"] >= 0 and stats["mrays_per_s"] >= 0
    assert 0 < stats["sample_sites"] <= W * H


def test_same_seed_same_image():
    a = dofray.render("paper", width=32, height=24, seed=3)
    b = dofray.render("paper", width=32, height=24, seed=3)
    np.testing.assert_array_equal(a.rgba, b.rgba)


def test_threads_do_not_change_the_image():
    one = dofray.render("paper", width=32, height=24, spp=4, threads=1)
    two = dofray.render("paper", width=32, height=24, spp=4, threads=2)
    np.testing.assert_array_equal(one.rgba, two.rgba)
    for bad in (0, -1, 5000):
        with pytest.raises(dofray.UsageError, match="threads"):
            dofray.render("paper", width=16, height=12, threads=bad)


def test_modes_and_overrides():
    r = dofray.render(
        "paper",
        width=32,
        mode="pinhole",
        aa=2,
        exposure=1.0,
        autofocus=(16, 20),
        blades=6,
        frame=0,
    )
    assert r.rgba.shape == (24, 32, 4)  # the height follows the scene's aspect
    d = dofray.render("paper", width=32, height=24, mode="dense", spp=4, aperture_radius=0.1)
    assert np.isfinite(d.rgba).all()
    # The direct integrator renders another image of the same scene.
    q = dofray.render("paper", width=32, height=24, mode="pinhole", integrator="direct")
    p = dofray.render("paper", width=32, height=24, mode="pinhole", integrator="path")
    assert np.isfinite(q.rgba).all() and not np.array_equal(q.rgba, p.rgba)


def test_save_png_and_exr(paper, tmp_path):
    png, exr = tmp_path / "out.png", tmp_path / "out.exr"
    paper.save(png)
    paper.save(str(exr))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert exr.read_bytes()[:4] == b"\x76\x2f\x31\x01"


def test_save_errors(paper, tmp_path):
    with pytest.raises(dofray.Error) as info:
        paper.save(tmp_path / "missing-dir" / "out.png")
    assert info.value.kind == "io"
    with pytest.raises(dofray.Error) as info:
        paper.save(tmp_path / "out.bmp")
    assert "bmp" in str(info.value)


def test_missing_scene_file(tmp_path):
    path = tmp_path / "no-such-scene.toml"
    with pytest.raises(dofray.Error) as info:
        dofray.render(path)
    assert info.value.kind == "bad_input"
    assert "no-such-scene.toml" in str(info.value)
    assert not isinstance(info.value, ValueError)


def test_unknown_builtin_scene():
    with pytest.raises(dofray.Error) as info:
        dofray.render("no-such-builtin")
    assert info.value.kind in ("bad_input", "usage")
    assert "no-such-builtin" in str(info.value)


def test_an_image_beyond_the_address_space_limit_is_an_error_not_an_abort():
    """Under an address-space limit (`ulimit -v`, set in a child interpreter), an image whose
    buffers cannot fit raises dofray.Error (kind resource_limit) naming the limit, and the
    interpreter lives on to render a small image."""
    import subprocess
    import sys

    child = """
import resource
import dofray
resource.setrlimit(resource.RLIMIT_AS, (3_000_000_000, resource.RLIM_INFINITY))
try:
    dofray.render("paper", width=1, height=200_000_000)
    print("no error")
except dofray.Error as e:
    print("error:", e.kind, e)
r = dofray.render("paper", width=32, height=24, spp=4)
print("survived", r.width, r.height)
"""
    out = subprocess.run(
        [sys.executable, "-c", child], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "error: resource_limit a 1x200000000 image" in out.stdout, out.stdout
    assert "address-space limit" in out.stdout, out.stdout
    assert "survived 32 24" in out.stdout, out.stdout


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        (dict(f_number=-1.0), "f_number"),
        (dict(f_number=float("nan")), "f_number"),
        (dict(focal_length=0.0), "focal_length"),
        (dict(width=0), "width"),
        (dict(height=-5), "height"),
        (dict(spp=0), "spp"),
        (dict(aa=100_000), "aa"),
        (dict(blades=2), "blades"),
        (dict(focus_distance=-1.0), "focus_distance"),
        (dict(aperture_radius=-0.5), "aperture_radius"),
        (dict(mode="sharp"), "mode"),
        (dict(exposure=1000.0), "exposure"),
        (dict(integrator="whitted"), "integrator"),
        (dict(tolerance=0.0), "tolerance"),
    ],
)
def test_bad_overrides(kwargs, name):
    with pytest.raises(dofray.UsageError) as info:
        dofray.render("paper", **{"width": 16, "height": 12, **kwargs})
    e = info.value
    assert isinstance(e, ValueError) and isinstance(e, dofray.Error)
    assert e.kind == "usage"
    assert name in str(e)


def test_unknown_keyword():
    with pytest.raises(TypeError, match="f_stop"):
        dofray.render("paper", f_stop=2.8)
    with pytest.raises(TypeError):
        dofray.render("paper", 64)  # overrides are keyword-only


def test_progress_is_called_with_monotone_done():
    calls = []
    caller = threading.get_ident()

    def progress(phase, done, total):
        assert threading.get_ident() == caller
        calls.append((phase, done, total))

    dofray.render("paper", width=160, height=120, mode="dense", spp=32, progress=progress)
    assert calls
    phases = []
    for phase, done, total in calls:
        assert isinstance(phase, str) and 0 <= done <= total
        if not phases or phases[-1][0] != phase:
            phases.append((phase, []))
        phases[-1][1].append(done)
    for phase, dones in phases:
        assert dones == sorted(dones), phase
    # The last call reports the finished render.
    phase, done, total = calls[-1]
    assert phase == "dense" and done == total


def test_gil_is_released():
    count = 0
    stop = threading.Event()

    def spin():
        nonlocal count
        while not stop.is_set():
            count += 1

    t = threading.Thread(target=spin)
    t.start()
    try:
        before = count
        dofray.render("paper", width=320, height=240, mode="dense", spp=16)
        during = count - before
    finally:
        stop.set()
        t.join()
    # A render holding the GIL would let the thread run only briefly at the 50 ms polls
    # (about 1.6 million increments in this render with the GIL released, on 2 cores).
    assert during > 100_000


def test_keyboard_interrupt_cancels(sigint_handled):
    # Many seconds of work; interrupted after 0.3 s it must stop (and not hang).
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            dofray.render("paper", width=800, height=600, mode="dense", spp=256)
    finally:
        timer.cancel()
    # The module still works afterwards.
    assert dofray.render("paper", width=16, height=12).rgba.shape == (12, 16, 4)


class Stop(Exception):
    pass


def test_progress_exception_cancels_and_propagates():
    calls = []

    def progress(phase, done, total):
        calls.append(done)
        if len(calls) >= 2:
            raise Stop("enough")

    with pytest.raises(Stop, match="enough"):
        dofray.render("paper", width=800, height=600, mode="dense", spp=256, progress=progress)
    assert len(calls) == 2


def test_progress_must_be_callable():
    with pytest.raises(TypeError, match="progress"):
        dofray.render("paper", width=16, height=12, progress=42)


def test_render_from_another_thread():
    out = {}

    def work():
        out["r"] = dofray.render("paper", width=16, height=12)

    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert out["r"].rgba.shape == (12, 16, 4)


LAMP = """
name = "lamp"
ambient = 0
[image]
width = 192
height = 144
[camera]
eye = [0, 0, 0]
look_at = [0, 0, 1]
f_number = 1.4
focal_length_mm = 85
sensor_width_mm = 36
focus_distance = 4
[background]
horizon = 0
zenith = 0
[[materials]]
name = "lamp"
diffuse = 0
emission = 400
[[objects]]
type = "sphere"
center = [0.01, 0.005, 0.9]
radius = 0.0005
material = "lamp"
"""


def test_light_tracing(tmp_path):
    # A 1 mm lamp blurred to a 24 px disc. Light-traced (the default), its image holds the
    # lamp's energy at every seed: radiance 400 over its projected area, pi r^2 (f / z)^2
    # square pixels, in each of three channels. Camera rays alone find it by luck: sample
    # reuse spreads each sample that does over the disc, so an image holds none of the
    # lamp or whole multiples of one sample's share, seed by seed.
    scene = tmp_path / "lamp.toml"
    scene.write_text(LAMP)
    energy = lambda r: float(r.rgba[..., :3].sum())
    f_px = 85 / 36 * 192
    expected = 3 * 400 * np.pi * 0.0005**2 * (f_px / 0.9) ** 2
    for seed in range(4):
        on = dofray.render(scene, spp=16, seed=seed)
        assert on.stats["light_paths"] > 0
        assert abs(energy(on) / expected - 1) < 0.02, (seed, energy(on), expected)
    off = [dofray.render(scene, spp=16, seed=seed, light_tracing=False) for seed in range(4)]
    assert all(r.stats["light_paths"] == 0 for r in off)
    assert max(map(energy, off)) > 2 * min(map(energy, off))


def test_reuse():
    # Sample reuse is on by default; off keeps every site to its own samples: the same
    # sites and samples (reuse only changes how they are combined), a different image.
    on = dofray.render("paper", width=96, height=72, spp=16)
    off = dofray.render("paper", width=96, height=72, spp=16, reuse=False)
    assert on.stats["rays"] == off.stats["rays"]
    assert on.stats["sample_sites"] == off.stats["sample_sites"]
    assert not np.array_equal(on.rgba, off.rgba)
    assert np.isfinite(on.rgba).all()
    with pytest.raises(TypeError):
        dofray.render("paper", width=8, height=8, reuse="yes")


LENSES = os.path.join(os.path.dirname(__file__), "..", "..", "lenses")


def test_real_lens(tmp_path):
    # A lens prescription traced element by element: its own focal length frames the shot
    # (the double Gauss is a 50 mm: the same framing as a thin 50 mm lens), the corners
    # vignette, and a bad lens file is bad input naming its line.
    lens = os.path.join(LENSES, "double-gauss-50mm.dat")
    real = dofray.render("paper", width=96, height=64, spp=8, mode="dense", lens=lens)
    thin = dofray.render(
        "paper", width=96, height=64, spp=8, mode="dense", f_number=2, focal_length=50
    )
    assert np.isfinite(real.rgba).all()
    centre = lambda r: float(r.rgba[24:40, 40:56, :3].mean())
    assert abs(centre(real) / centre(thin) - 1.0) < 0.15
    bad = tmp_path / "bad.dat"
    bad.write_text("# bad\n10 2 1.5\n")
    with pytest.raises(dofray.Error) as info:
        dofray.render("paper", width=32, height=24, spp=1, lens=bad)
    assert info.value.kind == "bad_input"
    assert "bad.dat:2" in str(info.value)
    # Thin-lens keywords beside a real lens are refused, naming the keyword.
    with pytest.raises(dofray.UsageError, match="aperture_radius"):
        dofray.render("paper", width=32, height=24, spp=1, lens=lens, aperture_radius=0.1)
