"""chiaro: one scene, every classic illumination and shading technique.

Load a scene file or build one in code, render it with any technique, and
get a numpy array of linear RGB back::

    import chiaro
    scene = chiaro.load("scenes/cornell-box.toml")
    img = chiaro.render(scene, technique="whitted", width=256, height=256)
    img.shape            # (256, 256, 3), float32, linear RGB
    chiaro.write("box.png", img)
    img                  # shows inline in Jupyter

Render settings are the CLI's ``--set`` keys: pass them as keyword
arguments with ``.`` written as ``__`` (``whitted__max_depth=3``) or as a
dict (``settings={"whitted.max_depth": 3}``).

Radiosity is view independent: :func:`solve_radiosity` solves it once and
``render(..., solution=sol)`` renders any camera or region from it
(techniques ``radiosity`` and ``hybrid``) without solving again.

Distributed rendering on a Ray cluster lives in :mod:`chiaro.distributed`.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _chiaro
from ._chiaro import (
    ChiaroError,
    RadiositySolution,
    RenderError,
    Scene,
    SceneError,
    SettingsError,
    has_crop,
    settings_keys,
    techniques,
)

__version__ = _chiaro.__version__

__all__ = [
    "ChiaroError",
    "Image",
    "RadiositySolution",
    "RenderError",
    "Scene",
    "SceneError",
    "SettingsError",
    "compare",
    "has_crop",
    "load",
    "loads",
    "metrics",
    "read_image",
    "render",
    "render_region",
    "settings_keys",
    "solve_radiosity",
    "techniques",
    "write",
]

PathLike = Union[str, "os.PathLike[str]"]
ProgressArg = Union[bool, None, Callable[[str, int, int], Any]]


class Image(np.ndarray):
    """A float32 ``(H, W, 3)`` linear-RGB image: a numpy array that also
    displays inline in Jupyter (``_repr_png_``, clamped and sRGB-encoded like
    the CLI's PNG output).

    Attributes (``None`` when not requested or not applicable):

    - ``depth``: ``(H, W)`` float32 eye distance of the first hit (``inf``
      for background), when rendered with ``aovs=True``;
    - ``normal``: ``(H, W, 3)`` float32 world-space shading normal, when
      rendered with ``aovs=True``;
    - ``stats``: dict with ``seconds`` (render time), ``rays`` (where the
      technique counts them), ``triangles`` and ``settings`` (every resolved
      render setting).
    """

    depth: Optional[np.ndarray]
    normal: Optional[np.ndarray]
    stats: Optional[dict]

    def __new__(cls, array: Any, depth=None, normal=None, stats=None) -> "Image":
        obj = np.asarray(array, dtype=np.float32).view(cls)
        obj.depth = depth
        obj.normal = normal
        obj.stats = stats
        return obj

    def __array_finalize__(self, obj: Any) -> None:
        # Views and slices keep the metadata only when they keep the shape.
        same = obj is not None and getattr(obj, "shape", None) == self.shape
        self.depth = getattr(obj, "depth", None) if same else None
        self.normal = getattr(obj, "normal", None) if same else None
        self.stats = getattr(obj, "stats", None) if same else None

    def to_png(self, tonemap: str = "clamp", exposure: float = 0.0) -> bytes:
        """The image as 8-bit sRGB PNG bytes (tone mapped: ``clamp``,
        ``reinhard`` or ``filmic``; exposure in stops)."""
        return _chiaro.encode_png(np.asarray(self, dtype=np.float32), tonemap, exposure)

    def _repr_png_(self) -> Optional[bytes]:
        if self.ndim != 3 or self.shape[2] != 3 or self.size == 0:
            return None
        return self.to_png()


def load(path: PathLike) -> Scene:
    """Reads a scene file: ``.toml`` (chiaro's format), ``.xml`` (Mitsuba 3),
    ``.pbrt`` (pbrt-v4, and v3 where they differ little), ``.obj``
    (+ ``.mtl``), ``.ply``, ``.gltf`` or ``.glb``.

    Raises :class:`SceneError` (with ``path``, ``line``, ``column`` set, or
    ``location`` for glTF JSON paths) for a file that does not parse or a
    scene that does not validate, and ``OSError`` (e.g.
    ``FileNotFoundError``) for a file that cannot be read. Loader warnings
    are issued as ``UserWarning``.
    """
    return _chiaro.load(os.fspath(path))


def loads(text: str, base_dir: Optional[PathLike] = None, name: str = "<string>") -> Scene:
    """Parses a ``.toml`` scene held in a string; relative paths in it
    resolve against ``base_dir`` (default: the current directory) and errors
    name ``name`` as the file."""
    return _chiaro.loads(text, None if base_dir is None else os.fspath(base_dir), name)


def _overrides(settings: Optional[Mapping[str, Any]], kwargs: Mapping[str, Any]) -> list:
    """Merges ``settings`` (dotted keys) and keyword settings (``__`` for
    ``.``) into a list of ``(key, value)`` pairs, dict first."""
    out = [(str(k), v) for k, v in (settings or {}).items()]
    out += [(k.replace("__", "."), v) for k, v in kwargs.items()]
    return out


class _Tqdm:
    """Adapts a ``(stage, done, total)`` callback to tqdm bars, one per stage."""

    def __init__(self, tqdm: Any) -> None:
        self._tqdm = tqdm
        self._bar = None
        self._stage = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if stage != self._stage or self._bar is None:
            self.close()
            self._stage = stage
            self._bar = self._tqdm(total=total or None, desc=stage or "render", leave=False)
        self._bar.n = done
        self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def _progress_callback(progress: ProgressArg):
    """A ``(callback, closer)`` pair for the ``progress`` argument: a callable
    is used as is; ``True`` means a tqdm bar when tqdm is installed (and no
    progress otherwise); ``None``/``False`` means none."""
    if callable(progress):
        return progress, None
    if progress:
        try:
            from tqdm.auto import tqdm  # type: ignore[import-not-found]
        except ImportError:
            return None, None
        bar = _Tqdm(tqdm)
        return bar, bar.close
    return None, None


def _render_native(
    scene: Scene,
    technique: Optional[str],
    width: Optional[int],
    height: Optional[int],
    samples: Optional[int],
    seed: Optional[int],
    settings: Optional[Mapping[str, Any]],
    kwargs: Mapping[str, Any],
    *,
    camera: Optional[Mapping[str, Any]] = None,
    region: Optional[Sequence[int]] = None,
    progress: ProgressArg = None,
    threads: Optional[int] = None,
    aovs: bool = False,
    solution: Optional[RadiositySolution] = None,
) -> Image:
    if not isinstance(scene, Scene):
        raise TypeError(f"expected a chiaro.Scene, got {type(scene).__name__}")
    callback, close = _progress_callback(progress)
    try:
        out = _chiaro.render(
            scene,
            technique=technique,
            width=width,
            height=height,
            samples=samples,
            seed=seed,
            overrides=_overrides(settings, kwargs),
            camera=None if camera is None else dict(camera),
            region=None if region is None else tuple(int(v) for v in region),
            progress=callback,
            threads=threads,
            aovs=aovs,
            solution=solution,
        )
    finally:
        if close is not None:
            close()
    stats = {k: out[k] for k in ("seconds", "rays", "triangles", "settings", "cropped")}
    return Image(out["color"], depth=out.get("depth"), normal=out.get("normal"), stats=stats)


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
) -> Image:
    """Renders ``scene`` and returns an :class:`Image` (a float32 numpy array
    of shape ``(height, width, 3)``, linear RGB).

    Settings start from the scene's ``[render]`` table and are overridden in
    the CLI's order: ``technique`` (one of :func:`techniques`), ``width``,
    ``height``, ``samples`` (per pixel), ``seed``, then ``settings`` (a dict
    of dotted keys, ``{"whitted.max_depth": 3}``), then keyword settings
    (``whitted__max_depth=3``; ``__`` stands for ``.``). See
    :func:`settings_keys` for every key. The same scene and settings give
    the same image as ``chiaro render`` on the command line.

    ``camera``: a dict replacing some of the scene camera's fields
    (``eye``, ``look_at``, ``up``, ``fov_y_degrees``, ``near``, ``far``) for
    this render only. ``aovs=True`` also fills ``image.depth`` and
    ``image.normal``. ``progress``: ``True`` for a tqdm bar (if tqdm is
    installed) or a callable ``f(stage, done, total)`` called about every
    50 ms from the calling thread; an exception it raises cancels the
    render. ``threads``: worker threads (default: all cores).
    ``solution``: a :class:`RadiositySolution` of this scene (from
    :func:`solve_radiosity`) to render from instead of solving, with
    technique ``radiosity`` (the solution displayed) or ``hybrid`` (ray
    tracing plus the solution's indirect light); the ``radiosity.*``
    settings are then those it was solved with. Raises
    :class:`SettingsError` for another technique and :class:`RenderError`
    for a solution of another scene.

    The GIL is released while rendering; Ctrl-C cancels the render and
    raises ``KeyboardInterrupt``. Raises :class:`SettingsError` for an
    unknown technique or setting, :class:`SceneError` for an invalid scene,
    :class:`RenderError` if the technique refuses the scene.
    """
    return _render_native(
        scene, technique, width, height, samples, seed, settings, kwargs,
        camera=camera, progress=progress, threads=threads, aovs=aovs, solution=solution,
    )


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
) -> Image:
    """Renders the pixels ``x0 <= x < x1``, ``y0 <= y < y1`` of the image
    :func:`render` would make with the same arguments, and returns them as
    an ``(y1 - y0, x1 - x0, 3)`` :class:`Image`, equal to the same slice of
    the whole render (pixel seeds derive from pixel and sample indices).

    When the renderer has a crop window (:func:`has_crop`), only the region
    is rendered; otherwise the whole image is rendered and the region cut
    out (``image.stats["cropped"]`` says which). ``solution``: as in
    :func:`render`; radiosity and hybrid renders from a solution shade only
    the region.
    """
    return _render_native(
        scene, technique, width, height, samples, seed, settings, kwargs,
        camera=camera, region=(x0, y0, x1, y1), progress=progress, threads=threads, aovs=aovs,
        solution=solution,
    )


def solve_radiosity(
    scene: Scene,
    *,
    settings: Optional[Mapping[str, Any]] = None,
    progress: ProgressArg = None,
    threads: Optional[int] = None,
    **kwargs: Any,
) -> RadiositySolution:
    """Solves the radiosity of ``scene`` once and returns the
    view-independent :class:`RadiositySolution`, for
    ``render(scene, "radiosity" or "hybrid", solution=sol)`` from any camera
    or region without solving again.

    Settings are given as for :func:`render` (only the ``radiosity.*`` keys
    matter: ``radiosity__solver="hierarchical"``, ``radiosity__patch_size``,
    ...). The GIL is released while solving; ``progress`` and Ctrl-C behave
    as in :func:`render`.

    The solution pickles, and ``sol.to_bytes()`` /
    ``RadiositySolution.from_bytes(scene, data)`` round-trip it (the JSON of
    ``chiaro render --save-solution``); ``from_bytes`` and rendering raise
    :class:`RenderError` for a solution of another scene (different
    geometry, materials, lights or patch size).
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"expected a chiaro.Scene, got {type(scene).__name__}")
    callback, close = _progress_callback(progress)
    try:
        return _chiaro.solve_radiosity(
            scene, overrides=_overrides(settings, kwargs), progress=callback, threads=threads
        )
    finally:
        if close is not None:
            close()


def write(
    path: PathLike,
    image: Any,
    *,
    depth: Any = None,
    normal: Any = None,
    tonemap: str = "clamp",
    exposure: float = 0.0,
    bit_depth16: bool = False,
) -> None:
    """Writes a linear-RGB ``(H, W, 3)`` image to ``path`` in the format of
    its extension: ``.png`` (8-bit sRGB, or 16-bit with ``bit_depth16``,
    tone mapped with ``tonemap`` and ``exposure`` stops), ``.exr`` (float,
    with depth and normal channels), ``.hdr``, ``.ppm``. The file is written
    atomically. For an :class:`Image` rendered with ``aovs=True`` its depth
    and normal are used unless given."""
    if depth is None:
        depth = getattr(image, "depth", None)
    if normal is None:
        normal = getattr(image, "normal", None)
    arr = np.asarray(image, dtype=np.float32)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"image: expected an array of shape (H, W, 3), got {arr.shape}")
    _chiaro.write(
        os.fspath(path), arr, depth, normal,
        tonemap, exposure, bit_depth16,
    )


def read_image(path: PathLike) -> Image:
    """Reads an image file (``.exr``, ``.hdr``, ``.png``, ...) as a linear-RGB
    float32 :class:`Image` (8-bit files are decoded from sRGB)."""
    return Image(_chiaro.read_image(os.fspath(path)))


def metrics(image: Any, reference: Any) -> dict:
    """The numbers ``chiaro compare`` (and the web viewer) report for
    ``image`` against ``reference``, two linear-RGB arrays of one shape
    ``(H, W, 3)`` (as :func:`render` returns them), computed by the same
    code: ``relative_mse`` and ``flip`` (the measures to rank by),
    ``display_psnr`` (dB of the clamped sRGB images), ``rmse``, ``psnr``
    (dB of linear radiance, peak 1) and ``mean_relative_error``. A PSNR is
    ``None`` when the images are identical. Raises ``ValueError`` for arrays
    of other shapes or of different sizes."""
    a = np.asarray(image, dtype=np.float32)
    b = np.asarray(reference, dtype=np.float32)
    if a.shape != b.shape:
        raise ValueError(f"metrics: image {a.shape} and reference {b.shape} differ in shape")
    return _chiaro.metrics(a, b)


def compare(
    scene: Scene,
    techniques: Sequence[str],
    *,
    reference: str = "path:auto",
    cache_dir: Optional[PathLike] = None,
    name: str = "scene",
    width: Optional[int] = None,
    height: Optional[int] = None,
    samples: Optional[int] = None,
    seed: Optional[int] = None,
    settings: Optional[Mapping[str, Any]] = None,
    progress: ProgressArg = None,
    **kwargs: Any,
) -> dict:
    """Renders ``scene`` with each of ``techniques`` and measures each
    against a reference, like ``chiaro compare``: ``"TECHNIQUE:SPP"``
    (``"path:1024"``) or ``"TECHNIQUE:auto[:CAP]"``, the default, the path
    tracer with samples added until its own estimated relMSE is below a
    tenth of the smallest it judges (at most CAP, default 4096). Returns the
    report as a dict: ``scene`` (``name``), ``width``, ``height``,
    ``psnr_convention``, ``reference`` (with ``spp`` and ``noise``: its own
    estimated ``relative_mse``, ``rmse``, ``psnr``, ``mean_relative_error``,
    the ``target_relative_mse`` and the number of ``batches``) and one entry per technique in ``techniques`` with
    ``relative_mse`` and ``flip`` (the measures to rank by: errors relative
    to each pixel's brightness, and NVIDIA's perceptual FLIP of the
    displayed images), ``display_psnr`` (dB of the clamped sRGB images),
    ``rmse``, ``psnr`` (dB, ``None`` when identical), ``mean_relative_error``,
    ``seconds`` and ``samples``."""
    native = getattr(_chiaro, "compare", None)
    if native is None:
        raise NotImplementedError("this build of chiaro has no compare()")
    callback, close = _progress_callback(progress)
    try:
        return native(
            scene, list(techniques), reference,
            None if cache_dir is None else os.fspath(cache_dir), name,
            width, height, samples, seed, _overrides(settings, kwargs), callback,
        )
    finally:
        if close is not None:
            close()
