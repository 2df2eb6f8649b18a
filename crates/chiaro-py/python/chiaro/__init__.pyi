"""Type stubs for chiaro (see __init__.py for the documentation)."""

import os
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, os.PathLike[str]]
ProgressArg = Union[bool, None, Callable[[str, int, int], Any]]
ArrayLike = npt.ArrayLike

class ChiaroError(Exception): ...

class SceneError(ChiaroError):
    path: Optional[str]
    line: Optional[int]
    column: Optional[int]
    location: Optional[str]

class SettingsError(ChiaroError): ...
class RenderError(ChiaroError): ...

class Scene:
    def __init__(self) -> None: ...
    def set_camera(
        self,
        eye: ArrayLike,
        look_at: ArrayLike,
        up: Optional[ArrayLike] = None,
        fov: Optional[float] = None,
        near: Optional[float] = None,
        far: Optional[float] = None,
    ) -> None: ...
    @property
    def camera(self) -> dict[str, Any]: ...
    @camera.setter
    def camera(self, camera: Mapping[str, Any]) -> None: ...
    def add_material(self, name: str, **props: Any) -> int: ...
    def add_light(self, kind: str, **props: Any) -> int: ...
    def add_mesh(
        self,
        positions: ArrayLike,
        indices: ArrayLike,
        normals: Optional[ArrayLike] = None,
        uvs: Optional[ArrayLike] = None,
        colors: Optional[ArrayLike] = None,
        name: str = "",
    ) -> int: ...
    def add_object(
        self,
        mesh: Optional[int] = None,
        sphere: Optional[float] = None,
        material: Union[int, str, None] = None,
        translate: Optional[ArrayLike] = None,
        rotate: Optional[ArrayLike] = None,
        scale: Union[float, ArrayLike, None] = None,
        matrix: Optional[ArrayLike] = None,
        smooth: bool = True,
        casts_shadows: bool = True,
        name: str = "",
    ) -> int: ...
    def set(self, key: str, value: Any) -> None: ...
    @property
    def settings(self) -> dict[str, Any]: ...
    @property
    def background(self) -> tuple[float, float, float]: ...
    @background.setter
    def background(self, value: Union[float, ArrayLike]) -> None: ...
    @property
    def materials(self) -> list[str]: ...
    @property
    def num_meshes(self) -> int: ...
    @property
    def num_objects(self) -> int: ...
    @property
    def num_lights(self) -> int: ...
    @property
    def triangle_count(self) -> int: ...
    def validate(self) -> list[str]: ...
    def is_valid(self) -> bool: ...
    def copy(self) -> Scene: ...
    def to_json(self) -> str: ...
    @staticmethod
    def from_json(text: str) -> Scene: ...

class RadiositySolution:
    @property
    def stats(self) -> dict[str, Any]: ...
    @property
    def element_count(self) -> int: ...
    def to_bytes(self) -> bytes: ...
    def check_scene(self, scene: Scene) -> None: ...
    @staticmethod
    def from_bytes(scene: Scene, data: bytes) -> RadiositySolution: ...
    def __reduce__(self) -> tuple[Any, tuple[bytes]]: ...

class Image(np.ndarray):
    depth: Optional[np.ndarray]
    normal: Optional[np.ndarray]
    stats: Optional[dict[str, Any]]
    def __new__(cls, array: ArrayLike, depth: Any = None, normal: Any = None, stats: Any = None) -> Image: ...
    def to_png(self, tonemap: str = "clamp", exposure: float = 0.0) -> bytes: ...
    def _repr_png_(self) -> Optional[bytes]: ...

def techniques() -> list[str]: ...
def settings_keys() -> list[str]: ...
def has_crop() -> bool: ...
def load(path: PathLike) -> Scene: ...
def loads(text: str, base_dir: Optional[PathLike] = None, name: str = "<string>") -> Scene: ...
def render(
    scene: Scene,
    technique: Optional[str] = None,
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    samples: Optional[int] = None,
    seed: Optional[int] = None,
    settings: Optional[Mapping[str, Any]] = None,
    camera: Optional[Mapping[str, Any]] = None,
    aovs: bool = False,
    progress: ProgressArg = None,
    threads: Optional[int] = None,
    solution: Optional[RadiositySolution] = None,
    **kwargs: Any,
) -> Image: ...
def render_region(
    scene: Scene,
    x0: int,
    y0: int,
    x1: int,
    y1: int,
    technique: Optional[str] = None,
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    samples: Optional[int] = None,
    seed: Optional[int] = None,
    settings: Optional[Mapping[str, Any]] = None,
    camera: Optional[Mapping[str, Any]] = None,
    aovs: bool = False,
    progress: ProgressArg = None,
    threads: Optional[int] = None,
    solution: Optional[RadiositySolution] = None,
    **kwargs: Any,
) -> Image: ...
def solve_radiosity(
    scene: Scene,
    *,
    settings: Optional[Mapping[str, Any]] = None,
    progress: ProgressArg = None,
    threads: Optional[int] = None,
    **kwargs: Any,
) -> RadiositySolution: ...
def write(
    path: PathLike,
    image: ArrayLike,
    *,
    depth: Optional[ArrayLike] = None,
    normal: Optional[ArrayLike] = None,
    tonemap: str = "clamp",
    exposure: float = 0.0,
    bit_depth16: bool = False,
) -> None: ...
def read_image(path: PathLike) -> Image: ...
def metrics(image: ArrayLike, reference: ArrayLike) -> dict[str, Optional[float]]: ...
def compare(
    scene: Scene,
    techniques: Sequence[str],
    *,
    reference: str = "path:256",
    cache_dir: Optional[PathLike] = None,
    name: str = "scene",
    width: Optional[int] = None,
    height: Optional[int] = None,
    samples: Optional[int] = None,
    seed: Optional[int] = None,
    settings: Optional[Mapping[str, Any]] = None,
    progress: ProgressArg = None,
    **kwargs: Any,
) -> dict[str, Any]: ...
