"""Distributed rendering on a Ray cluster.

:func:`render` splits an image into tiles (and an animation, given as a list
of cameras, into frames), renders each as a Ray task, and reassembles the
film. The scene is put into Ray's object store once and every task reads it
from there. Each task renders only its tile (the renderer's ``crop``
window), and the result equals a local :func:`chiaro.render` with the same
arguments: pixel for pixel, because every pixel's random numbers derive from
the pixel, the sample index and the seed, never from the tiling or the
thread count.

A task whose worker process dies (crash, node lost, OOM kill) is retried by
Ray up to ``max_retries`` times, so the image is still complete.

On a cluster::

    ray start --head                  # on the head node
    ray start --address=HEAD:6379     # on each other node
    python -c "import chiaro, chiaro.distributed as d; \\
               img = d.render(chiaro.load('scene.toml'), tiles=64, address='auto')"

or without writing Python::

    python -m chiaro.distributed scene.toml -o out.exr --address auto --tiles 64

Radiosity and hybrid: the radiosity solution is view independent, so it is
solved once, on the driver (:func:`chiaro.solve_radiosity`, or pass your own
``solution=``), put into the object store once as bytes, and every tile
task renders its window from it (each worker process decodes it once and
keeps it for its later tiles); no task solves. Both the radiosity display
and the hybrid ray tracer shade only the tile's pixels.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import OrderedDict
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

import chiaro
from chiaro import Image, RadiositySolution, Scene, _chiaro

Region = Tuple[int, int, int, int]

__all__ = ["render", "tile_grid", "main"]


def tile_grid(width: int, height: int, tiles: int) -> List[Region]:
    """Splits a ``width`` x ``height`` image into about ``tiles`` rectangles
    ``(x0, y0, x1, y1)`` (exclusive ends) that cover it exactly once: a grid
    of ``cols`` x ``rows`` cells as square as possible, with ``cols * rows``
    the smallest such product that is at least ``tiles`` (capped by the
    image size)."""
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    tiles = max(1, min(int(tiles), width * height))
    cols = max(1, min(width, round(math.sqrt(tiles * width / height))))
    rows = max(1, min(height, math.ceil(tiles / cols)))
    xs = [width * i // cols for i in range(cols + 1)]
    ys = [height * j // rows for j in range(rows + 1)]
    return [
        (xs[i], ys[j], xs[i + 1], ys[j + 1])
        for j in range(rows)
        for i in range(cols)
        if xs[i] < xs[i + 1] and ys[j] < ys[j + 1]
    ]


#: Techniques that render from a radiosity solution.
SOLUTION_TECHNIQUES = ("radiosity", "hybrid")

# Per worker process: decoded solutions by object-store id, newest last,
# so a worker decodes a shared solution once rather than once per tile.
_SOLUTIONS: "OrderedDict[str, RadiositySolution]" = OrderedDict()
_SOLUTIONS_KEPT = 2


def _shared_solution(scene: Scene, holder: Optional[List[Any]]) -> Optional[RadiositySolution]:
    """The solution whose bytes the driver put in the object store;
    ``holder`` is ``[ObjectRef]`` (wrapped so that Ray passes the reference,
    not the value, and this process can cache by its id), or ``None``."""
    if holder is None:
        return None
    import ray

    ref = holder[0]
    key = ref.hex()
    sol = _SOLUTIONS.get(key)
    if sol is None:
        sol = RadiositySolution.from_bytes(scene, ray.get(ref))
        _SOLUTIONS[key] = sol
        while len(_SOLUTIONS) > _SOLUTIONS_KEPT:
            _SOLUTIONS.popitem(last=False)
    else:
        _SOLUTIONS.move_to_end(key)
    return sol


def _tile_task(
    scene: Scene,
    job: Dict[str, Any],
    on_task_start: Optional[Callable[[Dict[str, Any]], None]],
) -> Tuple[int, Region, np.ndarray]:
    """One Ray task: renders ``job["region"]`` of frame ``job["frame"]``."""
    if on_task_start is not None:
        on_task_start(job)
    x0, y0, x1, y1 = job["region"]
    img = chiaro.render_region(
        scene, x0, y0, x1, y1,
        camera=job["camera"], threads=job["threads"],
        solution=_shared_solution(scene, job.get("solution")), **job["args"],
    )
    return job["frame"], job["region"], np.asarray(img, dtype=np.float32)


def render(
    scene: Scene,
    technique: Optional[str] = None,
    *,
    width: Optional[int] = None,
    height: Optional[int] = None,
    samples: Optional[int] = None,
    seed: Optional[int] = None,
    settings: Optional[Mapping[str, Any]] = None,
    tiles: int = 16,
    cameras: Optional[Sequence[Mapping[str, Any]]] = None,
    address: Optional[str] = None,
    max_retries: int = 3,
    cpus_per_task: int = 1,
    progress: Any = None,
    on_task_start: Optional[Callable[[Dict[str, Any]], None]] = None,
    ray_init: Optional[Mapping[str, Any]] = None,
    solution: Optional[RadiositySolution] = None,
    **kwargs: Any,
) -> Union[Image, List[Image]]:
    """Renders ``scene`` on a Ray cluster and returns the same
    :class:`chiaro.Image` as :func:`chiaro.render` with the same arguments
    (``technique``, ``width``, ``height``, ``samples``, ``seed``,
    ``settings``, keyword settings with ``__`` for ``.``).

    - ``tiles``: about how many tiles each frame is split into
      (see :func:`tile_grid`); each tile is one Ray task.
    - ``cameras``: an animation, one camera dict per frame (keys as in
      ``Scene.camera``, missing ones kept from the scene); a list of images
      is returned, one per frame.
    - ``address``: the Ray cluster to join (``"auto"`` for the one started
      by ``ray start``, ``"ray://host:10001"`` for Ray Client); ``None``
      starts a local one unless Ray is already initialised. ``ray_init``:
      extra ``ray.init`` keyword arguments.
    - ``max_retries``: how often Ray re-runs a task whose worker died.
    - ``cpus_per_task``: CPUs Ray reserves for each task, and the render
      threads the task uses.
    - ``progress``: ``True`` for a tqdm bar over tiles (when tqdm is
      installed) or a callable ``f("tiles", done, total)`` (preceded, for
      radiosity and hybrid, by the driver's ``f("radiosity ...", done,
      total)`` solve stages).
    - ``solution``: techniques ``radiosity`` and ``hybrid`` only: a
      :class:`chiaro.RadiositySolution` of ``scene`` to render from. Without
      it, the solution is solved once on the driver with these settings.
      Either way it goes into the object store once and is shared by every
      tile and frame (it is view independent); ``stats["solution"]`` has
      its stats.
    - ``on_task_start``: called inside the worker with the task's job dict
      (``frame``, ``region``, ...) before it renders: for logging,
      instrumentation, or fault-injection tests. It must be picklable.

    Settings are checked on the driver first, so a bad key raises
    :class:`chiaro.SettingsError` before any task is sent (as does
    ``solution`` with another technique).
    """
    import ray  # imported here so `import chiaro` works without Ray

    overrides = chiaro._overrides(settings, kwargs)
    resolved = _chiaro.resolve_settings(
        scene, technique, width, height, samples, seed, overrides
    )
    w, h = int(resolved["width"]), int(resolved["height"])
    args = dict(
        technique=technique, width=width, height=height, samples=samples, seed=seed,
        settings=dict(overrides),
    )
    uses_solution = str(resolved["technique"]) in SOLUTION_TECHNIQUES
    if solution is not None and not uses_solution:
        raise chiaro.SettingsError(
            f"solution= needs technique radiosity or hybrid, not {resolved['technique']}"
        )
    callback, close = chiaro._progress_callback(progress)
    start = time.perf_counter()
    try:
        if uses_solution and solution is None:
            # Solved once, here; the tiles only display it.
            solution = chiaro.solve_radiosity(scene, settings=dict(overrides), progress=callback)
        elif solution is not None:
            solution.check_scene(scene)  # refuse another scene's before any task
        return _run(
            ray, scene, solution, resolved, args, w, h, tiles, cameras, address,
            max_retries, cpus_per_task, callback, on_task_start, ray_init, start,
        )
    finally:
        if close is not None:
            close()


def _run(
    ray: Any,
    scene: Scene,
    solution: Optional[RadiositySolution],
    resolved: Dict[str, Any],
    args: Dict[str, Any],
    w: int,
    h: int,
    tiles: int,
    cameras: Optional[Sequence[Mapping[str, Any]]],
    address: Optional[str],
    max_retries: int,
    cpus_per_task: int,
    callback: Optional[Callable[[str, int, int], Any]],
    on_task_start: Optional[Callable[[Dict[str, Any]], None]],
    ray_init: Optional[Mapping[str, Any]],
    start: float,
) -> Union[Image, List[Image]]:
    """The body of :func:`render` once settings are checked and the
    solution (if any) is solved: joins or starts Ray, submits one task per
    tile and frame, and reassembles the images (``stats["seconds"]`` counts
    from ``start``, a ``time.perf_counter()``)."""
    if not ray.is_initialized():
        init = dict(ray_init or {})
        init.setdefault("include_dashboard", False)
        init.setdefault("log_to_driver", False)
        ray.init(address=address, **init)

    frames: List[Optional[Mapping[str, Any]]] = list(cameras) if cameras is not None else [None]
    regions = tile_grid(w, h, tiles)
    scene_ref = ray.put(scene)
    solution_holder = None if solution is None else [ray.put(solution.to_bytes())]
    task = ray.remote(num_cpus=cpus_per_task, max_retries=max_retries)(_tile_task)
    pending = [
        task.remote(
            scene_ref,
            {
                "frame": f,
                "region": r,
                "camera": None if cam is None else dict(cam),
                "threads": cpus_per_task,
                "args": args,
                "solution": solution_holder,
            },
            on_task_start,
        )
        for f, cam in enumerate(frames)
        for r in regions
    ]
    images = [np.zeros((h, w, 3), dtype=np.float32) for _ in frames]
    total, done = len(pending), 0
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        for frame, (x0, y0, x1, y1), tile in ray.get(ready):
            images[frame][y0:y1, x0:x1] = tile
            done += 1
        if callback is not None:
            callback("tiles", done, total)
    stats = {
        "seconds": time.perf_counter() - start,
        "tiles": len(regions),
        "frames": len(frames),
        "settings": resolved,
        "solution": None if solution is None else solution.stats,
    }
    out = [Image(img, stats=stats) for img in images]
    return out if cameras is not None else out[0]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m chiaro.distributed SCENE -o OUT [--address ADDR] [--tiles N]
    [--technique T] [--width W] [--height H] [--samples N] [--seed S]
    [--set KEY=VALUE ...]``: renders a scene file on a Ray cluster and
    writes the image (format from the extension, as ``chiaro render``).
    Returns the exit code: 0 on success, 1 for a scene, settings or render
    error, 2 for bad arguments."""
    p = argparse.ArgumentParser(
        prog="python -m chiaro.distributed",
        description="Render a chiaro scene on a Ray cluster.",
    )
    p.add_argument("scene", help="scene file (.toml, .xml, .pbrt, .obj, .ply, .gltf, .glb)")
    p.add_argument("-o", "--output", required=True, help="output image (.png, .exr, .hdr, .ppm)")
    p.add_argument("--address", default=None,
                   help="Ray cluster address ('auto' for `ray start`); default: a local cluster")
    p.add_argument("--tiles", type=int, default=16, help="about how many tiles (default 16)")
    p.add_argument("--technique", default=None)
    p.add_argument("--width", type=int, default=None)
    p.add_argument("--height", type=int, default=None)
    p.add_argument("--samples", type=int, default=None)
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a render setting, as `chiaro render --set`")
    p.add_argument("--max-retries", type=int, default=3)
    p.add_argument("--cpus-per-task", type=int, default=1)
    a = p.parse_args(argv)
    settings: Dict[str, Any] = {}
    for kv in a.set:
        if "=" not in kv:
            p.error(f"--set expects KEY=VALUE, got {kv!r}")
        k, v = kv.split("=", 1)
        settings[k.strip()] = _literal(v.strip())
    try:
        scene = chiaro.load(a.scene)
        img = render(
            scene, a.technique, width=a.width, height=a.height, samples=a.samples,
            seed=a.seed, settings=settings, tiles=a.tiles, address=a.address,
            max_retries=a.max_retries, cpus_per_task=a.cpus_per_task,
            progress=sys.stderr.isatty(),
        )
        r = img.stats["settings"]
        chiaro.write(a.output, img, tonemap=r["tonemap"], exposure=r["exposure"])
    except (chiaro.ChiaroError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(
        f"{a.output}: {r['technique']} {r['width']}x{r['height']} {r['samples']} spp, "
        f"{img.stats['tiles']} tiles in {img.stats['seconds']:.3f} s"
    )
    return 0


def _literal(text: str) -> Any:
    """A ``--set`` value: a JSON/TOML literal (number, ``true``, ``[0, 0, 1]``,
    ``"text"``) or, failing that, the bare text (``map``), as ``chiaro render
    --set`` reads it."""
    try:
        return json.loads(text)
    except ValueError:
        return text


if __name__ == "__main__":
    # Import the module under its real name so Ray pickles `_tile_task` by
    # reference (workers import chiaro.distributed) rather than from __main__.
    from chiaro import distributed as _self

    sys.exit(_self.main())
