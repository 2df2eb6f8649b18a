"""Distributed rendering on a real local Ray cluster (two CPUs, loopback):
tiles and frames reassemble into exactly the local render, a worker that
dies mid-render is retried, and the `python -m chiaro.distributed` CLI."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import chiaro
import chiaro.distributed as dist

BOX = "scenes/cornell-box.toml"


def test_tile_grid_covers_the_image_exactly_once():
    for w, h, n in [(64, 48, 6), (7, 5, 100), (1, 1, 4), (640, 480, 16), (33, 200, 7)]:
        cover = np.zeros((h, w), dtype=int)
        tiles = dist.tile_grid(w, h, n)
        for x0, y0, x1, y1 in tiles:
            assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h
            cover[y0:y1, x0:x1] += 1
        assert (cover == 1).all(), (w, h, n)
        assert len(tiles) >= min(n, w * h) or len(tiles) == w * h


@pytest.mark.parametrize("technique,samples", [("whitted", 1), ("phong", 2), ("path", 4)])
def test_tiled_render_equals_local_render(ray_cluster, root, technique, samples):
    scene = chiaro.load(root / BOX)
    local = chiaro.render(scene, technique, width=48, height=40, samples=samples, seed=3)
    tiled = dist.render(scene, technique, width=48, height=40, samples=samples, seed=3, tiles=7)
    assert tiled.shape == local.shape
    assert tiled.stats["tiles"] >= 7
    np.testing.assert_array_equal(np.asarray(tiled), np.asarray(local))


def test_animation_frames_equal_local_renders(ray_cluster, root):
    scene = chiaro.load(root / BOX)
    eye = scene.camera["eye"]
    cams = [{"eye": [eye[0] + dx, eye[1], eye[2]]} for dx in (-50.0, 0.0, 50.0)]
    frames = dist.render(scene, "phong", width=32, height=32, tiles=3, cameras=cams)
    assert len(frames) == 3
    for cam, frame in zip(cams, frames):
        np.testing.assert_array_equal(frame, chiaro.render(scene, "phong", width=32, height=32, camera=cam))
    assert not np.array_equal(frames[0], frames[2])


def test_a_worker_that_dies_is_retried_and_the_image_is_complete(ray_cluster, root, tmp_path):
    scene = chiaro.load(root / BOX)
    marker = str(tmp_path / "died-once")

    def die_once(job):
        # The first attempt of the first tile kills its worker process
        # outright (no exception, no cleanup), as a crash or OOM kill would.
        if job["region"][:2] == (0, 0) and not os.path.exists(marker):
            open(marker, "w").close()
            os._exit(1)

    img = dist.render(scene, "whitted", width=40, height=40, tiles=4, max_retries=2,
                      on_task_start=die_once)
    assert os.path.exists(marker), "the fault was injected"
    np.testing.assert_array_equal(img, chiaro.render(scene, "whitted", width=40, height=40))


def test_bad_settings_fail_on_the_driver(ray_cluster, root):
    scene = chiaro.load(root / BOX)
    with pytest.raises(chiaro.SettingsError):
        dist.render(scene, "phong", width=16, height=16, whitted__depth=2)


def test_module_cli_renders_on_the_cluster(ray_cluster, root, tmp_path):
    out = tmp_path / "box.exr"
    address = ray_cluster.get_runtime_context().gcs_address
    r = subprocess.run(
        [sys.executable, "-m", "chiaro.distributed", str(root / BOX), "-o", str(out),
         "--address", address, "--tiles", "4", "--technique", "whitted",
         "--width", "32", "--height", "24", "--set", "whitted.max_depth=2"],
        capture_output=True, text=True, timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert "4 tiles" in r.stdout
    scene = chiaro.load(root / BOX)
    local = chiaro.render(scene, "whitted", width=32, height=24, whitted__max_depth=2)
    np.testing.assert_array_equal(chiaro.read_image(out), local)
    bad = subprocess.run(
        [sys.executable, "-m", "chiaro.distributed", str(tmp_path / "none.toml"), "-o", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert bad.returncode == 1 and "none.toml" in bad.stderr


@pytest.mark.parametrize("technique", ["radiosity", "hybrid"])
def test_tiled_radiosity_is_solved_once_and_equals_local_render(
    ray_cluster, root, tmp_path, monkeypatch, technique
):
    scene = chiaro.load(root / BOX)
    fast = {"radiosity.solver": "hierarchical"}
    solves = []
    real_solve = chiaro.solve_radiosity

    def counting_solve(*a, **kw):
        solves.append(1)
        return real_solve(*a, **kw)

    monkeypatch.setattr(chiaro, "solve_radiosity", counting_solve)
    directory = str(tmp_path)

    def record_solution(job):
        # Runs in the worker (pickled by value): records the object-store id
        # of the solution this task was given.
        holder = job.get("solution")
        ref = "none" if holder is None else holder[0].hex()
        name = f"{job['frame']}-{'-'.join(map(str, job['region']))}"
        with open(os.path.join(directory, name), "w") as f:
            f.write(ref)

    eye = scene.camera["eye"]
    cams = [None, {"eye": [eye[0] + 60.0, eye[1], eye[2]]}]
    frames = dist.render(scene, technique, width=48, height=48, settings=fast, tiles=6,
                         cameras=[c or {} for c in cams],
                         on_task_start=record_solution)
    assert len(solves) == 1, "one solve on the driver for every tile and frame"
    refs = {p.read_text() for p in tmp_path.iterdir()}
    assert len(list(tmp_path.iterdir())) == 2 * frames[0].stats["tiles"]
    assert len(refs) == 1 and "none" not in refs, refs
    assert frames[0].stats["solution"]["solver"] == "hierarchical"
    monkeypatch.undo()
    for cam, frame in zip(cams, frames):
        local = chiaro.render(scene, technique, width=48, height=48, settings=fast, camera=cam)
        np.testing.assert_array_equal(np.asarray(frame), np.asarray(local))
    assert not np.array_equal(frames[0], frames[1])


def test_a_given_solution_is_shared_and_another_scenes_is_refused(ray_cluster, root):
    scene = chiaro.load(root / BOX)
    sol = chiaro.solve_radiosity(scene, radiosity__solver="hierarchical")
    img = dist.render(scene, "radiosity", width=32, height=32, tiles=4, solution=sol)
    np.testing.assert_array_equal(img, chiaro.render(scene, "radiosity", width=32, height=32, solution=sol))
    other = scene.copy()
    other.add_light("point", position=(278, 500, 278), intensity=1000)
    with pytest.raises(chiaro.RenderError, match="does not match this scene"):
        dist.render(other, "radiosity", width=16, height=16, tiles=2, solution=sol)
    with pytest.raises(chiaro.SettingsError, match="radiosity or hybrid"):
        dist.render(scene, "phong", width=16, height=16, solution=sol)
