"""Tests of dofray.render_jobs: frames and tiles rendered to files (run by scripts/python-test.sh)."""

import _thread
import os
import threading
from pathlib import Path

import pytest

import dofray

FOCUS_PULL = Path(__file__).resolve().parents[2] / "scenes" / "focus_pull.toml"
TINY = dict(width=32, height=24, spp=4, aa=1)


def test_frames_then_skip_existing(tmp_path):
    calls = []
    pattern = tmp_path / "frames" / "shot_##.png"
    run = dofray.render_jobs(
        FOCUS_PULL, pattern, frames="1-3", progress=lambda *a: calls.append(a), **TINY
    )
    assert (run["rendered"], run["skipped"], run["failed"], run["jobs"]) == (3, 0, 0, 3)
    outputs = [str(tmp_path / "frames" / f"shot_0{f}.png") for f in (1, 2, 3)]
    assert [job["output"] for job in run["frames"]] == outputs
    assert [job["frame"] for job in run["frames"]] == [1, 2, 3]
    assert all(job["status"] == "rendered" for job in run["frames"])
    assert run["frames"][0]["width"] == 32 and run["frames"][0]["primary_rays"] > 0
    assert calls == [(i, 3, i + 1, outputs[i]) for i in range(3)]
    assert all(os.path.isfile(p) for p in outputs)

    calls.clear()
    again = dofray.render_jobs(
        FOCUS_PULL, pattern, frames=[1, 2, 3], skip_existing=True,
        progress=lambda *a: calls.append(a), **TINY
    )
    assert (again["rendered"], again["skipped"]) == (0, 3)
    assert calls == []


def test_no_overwrite_with_fail_fast_stops_at_the_first(tmp_path):
    pattern = tmp_path / "shot_#.png"
    dofray.render_jobs(FOCUS_PULL, pattern, frames="1", **TINY)
    run = dofray.render_jobs(
        FOCUS_PULL, pattern, frames="1-3", no_overwrite=True, fail_fast=True, **TINY
    )
    assert (run["rendered"], run["failed"], run["not_run"]) == (0, 1, 2)
    error = run["frames"][0]["error"]
    assert error["kind"] == "io"
    assert "no_overwrite" in error["message"] and "shot_1.png" in error["message"]


def test_tiled_still_is_merged(tmp_path):
    still = tmp_path / "still.exr"
    run = dofray.render_jobs(FOCUS_PULL, still, tiles=(2, 2), **TINY)
    assert (run["rendered"], run["jobs"]) == (4, 4)
    assert run["merged"] == [str(still)]
    assert [job["tile"] for job in run["frames"]] == [0, 1, 2, 3]
    assert all(job["frame"] is None for job in run["frames"])
    assert still.is_file()
    assert not list(tmp_path.glob("still.tile-*"))


def test_a_shard_renders_its_share_and_merges_nothing(tmp_path):
    run = dofray.render_jobs(
        "paper", tmp_path / "p.png", tiles=(2, 1), shard=(1, 2), **TINY
    )
    assert (run["rendered"], run["jobs"], run["shard"]) == (1, 2, "1/2")
    assert run["merged"] == []
    assert (tmp_path / "p.tile-001.png").is_file()


def test_bad_arguments():
    with pytest.raises(dofray.UsageError, match="frames"):
        dofray.render_jobs(FOCUS_PULL, "one.png", frames="1-3", **TINY)
    with pytest.raises(dofray.UsageError, match="frame list"):
        dofray.render_jobs(FOCUS_PULL, "f_#.png", frames="1-x", **TINY)
    with pytest.raises(dofray.UsageError, match="skip_existing"):
        dofray.render_jobs("paper", "a.png", skip_existing=True, no_overwrite=True)
    with pytest.raises(dofray.UsageError, match="tiles"):
        dofray.render_jobs("paper", "a.png", tiles=(1000, 1), **TINY)
    with pytest.raises(dofray.UsageError, match="shard"):
        dofray.render_jobs("paper", "a.png", shard=(2, 2))
    with pytest.raises(dofray.UsageError, match="spp"):
        dofray.render_jobs("paper", "a.png", width=16, height=12, spp=0)
    with pytest.raises(TypeError, match="frame"):
        dofray.render_jobs("paper", "a.png", frame=3)
    with pytest.raises(TypeError, match="progress"):
        dofray.render_jobs("paper", "a.png", progress=42)
    with pytest.raises(dofray.Error) as e:
        dofray.render_jobs("/nonexistent/scene.toml", "a.png")
    assert e.value.kind == "bad_input"


class Stop(Exception):
    pass


def test_progress_exception_cancels_the_run(tmp_path):
    def progress(index, count, frame, output):
        if index == 1:
            raise Stop("enough")

    with pytest.raises(Stop, match="enough"):
        dofray.render_jobs(
            FOCUS_PULL, tmp_path / "s_##.png", frames="1-3", progress=progress, **TINY
        )
    # Each job waits for the callback: the second never rendered.
    assert (tmp_path / "s_01.png").is_file()
    assert not (tmp_path / "s_02.png").exists() and not (tmp_path / "s_03.png").exists()


def test_keyboard_interrupt_cancels_the_run(tmp_path, sigint_handled):
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            dofray.render_jobs(
                "paper", tmp_path / "big.png", tiles=(4, 4), width=800, height=600,
                mode="dense", spp=256,
            )
    finally:
        timer.cancel()
    assert not (tmp_path / "big.png").exists()


def test_a_scene_view_reaches_the_png(tmp_path):
    # A scene file's [view] (what the Blender add-on writes) is how every front end's PNGs
    # look, not only the command line's.
    scene = tmp_path / "viewed.toml"
    scene.write_text(FOCUS_PULL.read_text() + '\n[view]\ntransform = "AgX"\n')
    out = tmp_path / "still.png"
    run = dofray.render_jobs(scene, out, **TINY)
    assert run["rendered"] == 1
    # The PNG's tEXt chunks, read by hand (no imaging library needed).
    data = out.read_bytes()
    texts, pos = {}, 8
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"tEXt":
            k, _, v = body.partition(b"\0")
            texts[k.decode()] = v.decode("latin-1")
        pos += 12 + n
    assert texts["dofray:view"] == "AgX"
