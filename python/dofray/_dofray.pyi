"""Type hints of the extension module (see dofray/__init__.py for the documented API)."""

from typing import Any, Callable, Dict, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class Render:
    """A finished render."""

    @property
    def rgba(self) -> npt.NDArray[np.float32]:
        """(height, width, 4) linear RGB and alpha."""
    @property
    def depth(self) -> npt.NDArray[np.float32]:
        """(height, width) distance along the view axis; inf where nothing was hit."""
    @property
    def coc(self) -> npt.NDArray[np.float32]:
        """(height, width) circle-of-confusion diameter in pixels."""
    @property
    def stats(self) -> Dict[str, Any]:
        """rays (primary, shadow, secondary, total), seconds, mrays_per_s, sample_sites, ..."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    def save(self, path: Any) -> None:
        """Write the image as rendered: PNG or EXR by the extension."""

def render(
    scene: str,
    *,
    width: Optional[int] = ...,
    height: Optional[int] = ...,
    f_number: Optional[float] = ...,
    focal_length: Optional[float] = ...,
    sensor_width: Optional[float] = ...,
    focus_distance: Optional[float] = ...,
    autofocus: Optional[Tuple[int, int]] = ...,
    aperture_radius: Optional[float] = ...,
    blades: Optional[int] = ...,
    lens: Optional[str] = ...,
    spp: Optional[int] = ...,
    aa: Optional[int] = ...,
    mode: Optional[str] = ...,
    tolerance: Optional[float] = ...,
    seed: Optional[int] = ...,
    exposure: Optional[float] = ...,
    transparent: bool = ...,
    integrator: Optional[str] = ...,
    light_tracing: Optional[bool] = ...,
    reuse: Optional[bool] = ...,
    frame: Optional[int] = ...,
    threads: Optional[int] = ...,
    progress: Optional[Callable[[str, int, int], object]] = ...,
) -> Render: ...

def render_jobs(
    scene: str,
    output: str,
    *,
    frames: Optional[Union[str, Sequence[int]]] = ...,
    tiles: Optional[Tuple[int, int]] = ...,
    skip_existing: bool = ...,
    no_overwrite: bool = ...,
    fail_fast: bool = ...,
    shard: Optional[Tuple[int, int]] = ...,
    progress: Optional[Callable[[int, int, Optional[int], str], object]] = ...,
    **overrides: Any,
) -> Dict[str, Any]: ...
