"""Type stubs of the extension module `splat._splat` (the Rust side of the package)."""

from os import PathLike
from typing import Any, Callable, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

SH_C0: float

class SplatError(ValueError): ...

class Scene:
    @staticmethod
    def load(path: Union[str, PathLike], **options: Any) -> "Scene": ...
    @staticmethod
    def demo() -> "Scene": ...
    @staticmethod
    def from_arrays(
        means: npt.NDArray[np.float32],
        scales: npt.NDArray[np.float32],
        rotations: npt.NDArray[np.float32],
        opacities: npt.NDArray[np.float32],
        sh: npt.NDArray[np.float32],
        log_scales: bool,
        logit_opacities: bool,
    ) -> "Scene": ...
    def to_arrays(self) -> dict[str, npt.NDArray[np.float32]]: ...
    def __len__(self) -> int: ...
    @property
    def sh_degree(self) -> int: ...
    @property
    def triangles(self) -> int: ...
    @property
    def screen_filter(self) -> str: ...
    @property
    def trained(self) -> Optional[dict[str, Any]]: ...
    @property
    def camera(self) -> Optional["Camera"]: ...

class Camera:
    @staticmethod
    def look_at(
        eye: Sequence[float],
        target: Sequence[float],
        up: Sequence[float] = (0.0, 1.0, 0.0),
        fov_y: float = 50.0,
        width: int = 640,
        height: int = 480,
    ) -> "Camera": ...
    @staticmethod
    def from_matrices(viewmat: Any, intrinsics: Any, width: int, height: int) -> "Camera": ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def viewmat(self) -> npt.NDArray[np.float32]: ...
    @property
    def K(self) -> npt.NDArray[np.float32]: ...
    @property
    def is_pinhole(self) -> bool: ...
    @property
    def lens(self) -> str: ...
    @property
    def distortion(self) -> Optional[dict[str, list[float]]]: ...
    def undistorted(self, undistort: str) -> "Camera": ...
    def rescaled(self, width: int, height: int) -> "Camera": ...
    def downscaled(self, factor: int) -> "Camera": ...
    def undistort_photo(self, photo: npt.NDArray[np.uint8], undistort: str) -> npt.NDArray[np.uint8]: ...
    def undistortion_mask(self, undistort: str) -> Optional[npt.NDArray[np.bool_]]: ...
    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]: ...

class Renderer:
    def __init__(self, scene: Scene, /, **options: Any) -> None: ...
    def render(
        self, view: Camera, /, *, progress: Optional[Callable[[int, int], Any]] = None
    ) -> dict[str, Any]: ...
    def close(self) -> None: ...

def load_cameras(
    path: Union[str, PathLike],
    dataparser_transforms: Optional[Union[str, PathLike]] = None,
    undistort: Optional[str] = None,
    split: Optional[str] = None,
    data_factor: Optional[int] = None,
    image_size: Optional[tuple[int, int]] = None,
    gsplat_world: Optional[Scene] = None,
    world_transform: Optional[Union[str, PathLike]] = None,
    world_rows: Optional[list[list[float]]] = None,
) -> list[tuple[str, Camera]]: ...
def render(
    scene: Scene,
    view: Optional[Camera] = None,
    /,
    *,
    progress: Optional[Callable[[int, int], Any]] = None,
    **options: Any,
) -> dict[str, Any]: ...
def render_views(
    scene: Scene,
    views: Sequence[Camera],
    /,
    *,
    progress: Optional[Callable[[int, int], Any]] = None,
    **options: Any,
) -> list[dict[str, Any]]: ...
def methods() -> list[dict[str, Any]]: ...
def compare(
    reference: npt.NDArray[np.float32], test: npt.NDArray[np.float32], pixels_per_degree: Optional[float] = None
) -> dict[str, Optional[float]]: ...
def z_test(
    mean: npt.NDArray[np.float32],
    variance: npt.NDArray[np.float32],
    reference: npt.NDArray[np.float32],
    frames: int,
    mean_variance: Optional[npt.NDArray[np.float32]] = None,
    variance_frames: Optional[int] = None,
) -> dict[str, Any]: ...
def merge(parts: list[dict[str, Any]]) -> dict[str, Any]: ...
def power(
    expectation: npt.NDArray[np.float32],
    variance: npt.NDArray[np.float32],
    reference: npt.NDArray[np.float32],
    frames: int,
) -> dict[str, Any]: ...
