"""dofray: a depth-of-field ray tracer on Intel Embree.

>>> import dofray
>>> r = dofray.render("paper", width=64, height=48, f_number=2.8)
>>> r.rgba.shape, r.depth.shape, r.coc.shape
((48, 64, 4), (48, 64), (48, 64))
>>> r.save("paper.png")

``render`` runs on threads of its own with the GIL released; Ctrl-C (KeyboardInterrupt)
cancels it, and so does an exception raised by the ``progress`` callback.
"""

from __future__ import annotations

import os
from typing import Callable, Optional, Tuple, Union

from ._dofray import Render, __version__
from ._dofray import render as _render

__all__ = ["Error", "UsageError", "Render", "render", "__version__"]


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
    spp: Optional[int] = None,
    aa: Optional[int] = None,
    mode: Optional[str] = None,
    tolerance: Optional[float] = None,
    seed: Optional[int] = None,
    exposure: Optional[float] = None,
    transparent: bool = False,
    frame: Optional[int] = None,
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
      blades (0: circular);
    - ``focus_distance``: along the view axis (``float("inf")``: infinity);
      ``autofocus``: focus on the surface seen through pixel ``(x, y)``;
    - ``mode``: ``"adaptive"`` (default), ``"dense"`` or ``"pinhole"``; ``spp``: samples
      per defocused site; ``aa``: samples per in-focus site; ``tolerance``: the adaptive
      error tolerance in 8-bit code values; ``seed``; ``exposure`` in stops;
    - ``transparent``: the background contributes nothing (alpha is the coverage and RGB
      is premultiplied);
    - ``frame``: the frame of an animated scene (default: its first);
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
        spp=spp,
        aa=aa,
        mode=mode,
        tolerance=tolerance,
        seed=seed,
        exposure=exposure,
        transparent=transparent,
        frame=frame,
        progress=progress,
    )
