"""dofray: a depth-of-field ray tracer on Intel Embree.

>>> import dofray
>>> r = dofray.render("paper", width=64, height=48, f_number=2.8)
>>> r.rgba.shape, r.depth.shape, r.coc.shape
((48, 64, 4), (48, 64), (48, 64))
>>> r.save("paper.png")

``render`` runs on threads of its own with the GIL released; Ctrl-C (KeyboardInterrupt)
cancels it, and so does an exception raised by the ``progress`` callback.

``render_jobs`` renders frames and tiles to files as ``dofray render -o`` does:

>>> run = dofray.render_jobs("scenes/focus_pull.toml", "out/shot_####.exr", frames="1-3")
>>> run["rendered"], [job["output"] for job in run["frames"]]
(3, ['out/shot_0001.exr', 'out/shot_0002.exr', 'out/shot_0003.exr'])
"""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Optional, Sequence, Tuple, Union

from ._dofray import Render, __version__
from ._dofray import render as _render
from ._dofray import render_jobs as _render_jobs

__all__ = ["Error", "UsageError", "Render", "render", "render_jobs", "__version__"]


class Error(RuntimeError):
    """A render failed. ``kind`` says why, as ``dofray --json`` does: ``"usage"``,
    ``"bad_input"`` (a scene, model or texture that cannot be read or is invalid), ``"io"``
    (an output that cannot be written), ``"resource_limit"``, ``"interrupted"`` or
    ``"internal"``. The message is the library's."""

    kind: str = "internal"


class UsageError(Error, ValueError):
    """An argument out of range (``kind == "usage"``); the message names the keyword."""

    kind: str = "usage"


ProgressCallback = Callable[[str, int, int], object]


def render(
    scene: Union[str, "os.PathLike[str]"],
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    f_number: Optional[float] = None,
    focal_length: Optional[float] = None,
    sensor_width: Optional[float] = None,
    focus_distance: Optional[float] = None,
    autofocus: Optional[Tuple[int, int]] = None,
    aperture_radius: Optional[float] = None,
    blades: Optional[int] = None,
    lens: Optional[Union[str, "os.PathLike[str]"]] = None,
    spp: Optional[int] = None,
    aa: Optional[int] = None,
    mode: Optional[str] = None,
    tolerance: Optional[float] = None,
    seed: Optional[int] = None,
    exposure: Optional[float] = None,
    transparent: bool = False,
    integrator: Optional[str] = None,
    light_tracing: Optional[bool] = None,
    reuse: Optional[bool] = None,
    frame: Optional[int] = None,
    threads: Optional[int] = None,
    progress: Optional[ProgressCallback] = None,
) -> Render:
    """Render ``scene`` and return a :class:`Render` (``rgba``, ``depth``, ``coc``,
    ``stats``, ``save(path)``).

    ``scene`` is a built-in scene name (``"paper"``, ...) or a ``.toml``, ``.obj``,
    ``.gltf`` or ``.glb`` path. Every keyword is optional and overrides the scene's value,
    as the ``dofray render`` flag of the same name does:

    - ``width``, ``height``: image size in pixels (one alone keeps the aspect);
    - ``f_number``, ``focal_length`` (mm), ``sensor_width`` (mm): a photographic lens;
      ``aperture_radius``: a lens of this radius in scene units; ``blades``: aperture
      blades (0: circular); ``lens``: a real lens, the path of a lens prescription file
      traced element by element (see ``lenses/`` and ``docs/lenses.md``; ``f_number``
      stops it down and ``sensor_width`` sizes its film);
    - ``focus_distance``: along the view axis (``float("inf")``: infinity);
      ``autofocus``: focus on the surface seen through pixel ``(x, y)``;
    - ``mode``: ``"adaptive"`` (default), ``"dense"`` or ``"pinhole"``; ``spp``: samples
      per defocused site; ``aa``: samples per in-focus site; ``tolerance``: the adaptive
      error tolerance in 8-bit code values; ``seed``; ``exposure`` in stops;
    - ``transparent``: the background contributes nothing (alpha is the coverage and RGB
      is premultiplied);
    - ``integrator``: ``"path"`` (default: physically based, as Cycles) or ``"direct"``
      (the seed's quick direct shading); ``light_tracing``: ``False`` leaves lamps much
      smaller on screen than their blur, and lamps' highlights on glossy surfaces out of
      focus, to camera rays alone (default ``True``: traced from the light too, clean bokeh
      discs; unbiased either way); ``reuse``: ``False`` keeps each adaptive site to its
      own samples (default ``True``: blurred sites still noisy borrow their neighbours'
      samples of the same surface points; less noise in blurred matte and glossy surfaces);
    - ``frame``: the frame of an animated scene (default: its first);
    - ``threads``: worker threads, 1 to 1024 (default: all cores); the image is the same
      for any number;
    - ``progress``: called on the calling thread as ``progress(phase, done, total)`` while
      the render runs (``done`` grows within a phase); if it raises, the render is
      cancelled and the exception propagates.

    Raises :class:`UsageError` (a ``ValueError``) for a value out of range,
    :class:`Error` for anything else (``kind`` says what), ``KeyboardInterrupt`` when
    interrupted (the render stops promptly).
    """
    return _render(
        os.fspath(scene),
        width=width,
        height=height,
        f_number=f_number,
        focal_length=focal_length,
        sensor_width=sensor_width,
        focus_distance=focus_distance,
        autofocus=autofocus,
        aperture_radius=aperture_radius,
        blades=blades,
        lens=None if lens is None else os.fspath(lens),
        spp=spp,
        aa=aa,
        mode=mode,
        tolerance=tolerance,
        seed=seed,
        exposure=exposure,
        transparent=transparent,
        integrator=integrator,
        light_tracing=light_tracing,
        reuse=reuse,
        frame=frame,
        threads=threads,
        progress=progress,
    )


JobProgressCallback = Callable[[int, int, Optional[int], str], object]


def render_jobs(
    scene: Union[str, "os.PathLike[str]"],
    output: Union[str, "os.PathLike[str]"],
    *,
    frames: Optional[Union[str, Sequence[int]]] = None,
    tiles: Optional[Tuple[int, int]] = None,
    skip_existing: bool = False,
    no_overwrite: bool = False,
    fail_fast: bool = False,
    shard: Optional[Tuple[int, int]] = None,
    progress: Optional[JobProgressCallback] = None,
    **overrides: Any,
) -> Dict[str, Any]:
    """Render ``scene``'s frames, or tiles, to image files, as ``dofray render -o output``
    with the flags of the same names does, and return the run's summary.

    ``output`` is the image's path, PNG or EXR by its extension; a run of ``#`` in it
    becomes the zero-padded frame number (``shot_####.exr`` -> ``shot_0007.exr``). Folders
    are made; each file is written to a temporary file and renamed, so a file that exists is
    complete.

    - ``frames``: a frame list as ``--frames`` takes it (``"1-48"``, ``"1-240x2"``,
      ``"1,5,10..20"``) or a sequence of frame numbers; by default every frame of the
      scene's animation when ``output`` has a frame pattern, else one image;
    - ``tiles``: ``(columns, rows)``: each image rendered as tiles written next to it
      (``still.tile-003.exr``), merged into it and removed once all are rendered (without
      ``shard``);
    - ``skip_existing``: skip a job whose file (or whole image) exists; ``no_overwrite``:
      such a job fails instead; ``fail_fast``: stop at the first failure;
    - ``shard``: ``(index, count)``: render only jobs ``index``, ``index + count``, ... of
      the whole run (a render farm's worker);
    - ``progress``: called on the calling thread as ``progress(index, count, frame,
      output)`` before each job that renders (``frame`` is None for a single image); if it
      raises, the run is cancelled and the exception propagates;
    - ``overrides``: the keywords of :func:`render` but ``frame`` (``width``, ``f_number``,
      ``spp``, ``mode``, ...).

    The summary is the object ``dofray render --json`` prints for a run of jobs: the counts
    ``rendered``, ``skipped``, ``failed``, ``not_run`` (after ``fail_fast``) and ``jobs``
    (every shard's), ``merged`` (images assembled from tiles), ``seconds``, and ``frames``,
    one dict per job attempted: ``frame``, ``tile``, ``output``, ``status``
    (``"rendered"``, ``"skipped"`` or ``"failed"``), a rendered job's statistics, a failed
    job's ``error`` (``kind``, ``message``). A job that fails does not raise.

    Raises :class:`UsageError` for a bad keyword value or combination (frames without a
    frame pattern in ``output``, ``skip_existing`` with ``no_overwrite``, ...),
    :class:`Error` for a scene that cannot be loaded or a folder that cannot be made,
    ``KeyboardInterrupt`` when interrupted (the files written so far stay; rerun with
    ``skip_existing`` to resume).
    """
    return _render_jobs(
        os.fspath(scene),
        os.fspath(output),
        frames=frames,
        tiles=tiles,
        skip_existing=skip_existing,
        no_overwrite=no_overwrite,
        fail_fast=fail_fast,
        shard=shard,
        progress=progress,
        **overrides,
    )
