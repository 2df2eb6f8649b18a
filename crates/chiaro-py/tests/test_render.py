"""The Python module against the CLI and its own contracts: same pictures as
`chiaro render`, scenes from numpy arrays, errors with line and column,
settings, regions, pickling, progress and Ctrl-C, output files, compare."""

from __future__ import annotations

import _thread
import pickle
import threading

import numpy as np
import pytest

import chiaro
from conftest import run

BOX = "scenes/cornell-box.toml"
WHITTED = "scenes/whitted.toml"


@pytest.mark.parametrize(
    "technique,extra",
    [("phong", []), ("whitted", ["--set", "whitted.max_depth=2"]), ("path", ["--set", "path.max_depth=3"])],
)
def test_python_render_equals_cli_exr(root, cli, tmp_path, technique, extra):
    out = tmp_path / f"{technique}.exr"
    run(cli + ["render", str(root / BOX), "--technique", technique, "--width", "40",
               "--height", "32", "--samples", "2", "--seed", "7", *extra, "-o", str(out)])
    from_cli = chiaro.read_image(out)
    settings = dict(kv.split("=") for kv in extra[1::2])
    settings = {k: int(v) for k, v in settings.items()}
    img = chiaro.render(chiaro.load(root / BOX), technique, width=40, height=32, samples=2,
                        seed=7, settings=settings)
    assert img.shape == (32, 40, 3) and img.dtype == np.float32
    assert np.isfinite(img).all()
    assert img.mean() > 0.01, "the Cornell box must not render black"
    np.testing.assert_array_equal(np.asarray(img), np.asarray(from_cli))


def test_python_render_equals_cli_png_roundtrip(root, cli, tmp_path):
    out = tmp_path / "box.png"
    run(cli + ["render", str(root / BOX), "--technique", "gouraud", "--width", "32",
               "--height", "32", "-o", str(out)])
    img = chiaro.render(chiaro.load(root / BOX), "gouraud", width=32, height=32)
    py_png = tmp_path / "py.png"
    chiaro.write(py_png, img)
    assert py_png.read_bytes() == out.read_bytes()
    # Decoded 8-bit sRGB is within one code value of the clamped linear render.
    back = chiaro.read_image(out)
    assert np.abs(np.asarray(back) - np.clip(img, 0, 1)).max() < 0.02


def numpy_scene() -> chiaro.Scene:
    """A red triangle facing the camera in front of a grey floor quad, lit by
    a point light; built only from numpy arrays and keyword properties."""
    s = chiaro.Scene()
    s.set_camera(eye=(0, 0, 4), look_at=(0, 0, 0), fov=45)
    red = s.add_material("red", diffuse=[0.9, 0.1, 0.1], ambient=0.0)
    grey = s.add_material("grey", diffuse=0.5)
    tri = s.add_mesh(np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], dtype=np.float64),
                     np.array([[0, 1, 2]]))
    quad = s.add_mesh(np.array([[-3, -1.5, 3], [3, -1.5, 3], [3, -1.5, -3], [-3, -1.5, -3]], np.float32),
                      np.array([[0, 1, 2], [0, 2, 3]], np.int32))
    s.add_object(mesh=tri, material=red)
    s.add_object(mesh=quad, material="grey", name="floor")
    s.add_object(sphere=0.3, material=grey, translate=(1.5, 0.5, 0))
    s.add_light("point", position=[0, 2, 4], intensity=20.0)
    s.background = (0.0, 0.0, 0.2)
    return s


def test_scene_from_numpy_renders():
    s = numpy_scene()
    assert s.num_meshes == 2 and s.num_objects == 3 and s.triangle_count == 3
    assert s.is_valid(), s.validate()
    for technique in ("phong", "whitted"):
        img = chiaro.render(s, technique, width=32, height=32)
        assert np.isfinite(img).all()
        centre = img[16, 16]
        assert centre[0] > 0.05 and centre[0] > 3 * centre[1], (technique, centre)
        np.testing.assert_allclose(img[0, 0], [0.0, 0.0, 0.2], atol=1e-6)


def test_scene_builder_errors():
    s = chiaro.Scene()
    with pytest.raises(ValueError, match="no material"):
        s.add_object(sphere=1.0)
    s.add_material("m", diffuse=0.5)
    with pytest.raises(ValueError, match="unknown property `difuse`"):
        s.add_material("x", difuse=0.5)
    with pytest.raises(IndexError, match="vertex 5"):
        s.add_mesh(np.zeros((3, 3)), np.array([[0, 1, 5]]))
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        s.add_mesh(np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(KeyError, match="unknown material"):
        s.add_object(sphere=1.0, material="nope")
    with pytest.raises(ValueError, match="unknown light type"):
        s.add_light("laser")
    with pytest.raises(ValueError, match="shape"):
        s.add_light("area", intensity=3.0)
    s.add_light("area", shape={"quad": {"corner": [0, 1, 0], "edge_u": [1, 0, 0], "edge_v": [0, 0, 1]}})
    assert s.num_lights == 1


def test_bad_scene_raises_with_line_and_column(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[render]\ntechnique = "phong"\nwidth = "wide"\n')
    with pytest.raises(chiaro.SceneError) as e:
        chiaro.load(bad)
    assert e.value.line == 3 and e.value.column == 9, str(e.value)
    assert e.value.path == str(bad)
    assert str(e.value).startswith(f"{bad}:3:9:")
    with pytest.raises(chiaro.SceneError) as e:
        chiaro.loads("[camera]\nfov = 40\n\n[[object]]\nprimitive = 'sphere'\nmaterial = 'nope'\n", name="s.toml")
    assert e.value.path == "s.toml" and e.value.line is not None
    with pytest.raises(FileNotFoundError):
        chiaro.load(tmp_path / "missing.toml")
    assert issubclass(chiaro.SceneError, chiaro.ChiaroError)


def test_settings_keywords_dict_and_set(root):
    s = chiaro.load(root / WHITTED)
    a = chiaro.render(s, "whitted", width=24, height=24, whitted__max_depth=1)
    b = chiaro.render(s, "whitted", width=24, height=24, settings={"whitted.max_depth": 1})
    deep = chiaro.render(s, "whitted", width=24, height=24, whitted__max_depth=5)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, deep), "max_depth must change a scene with mirrors"
    assert a.stats["settings"]["whitted"]["max_depth"] == 1
    s.set("whitted.max_depth", 1)
    np.testing.assert_array_equal(chiaro.render(s, "whitted", width=24, height=24), a)
    with pytest.raises(chiaro.SettingsError, match="whitted.max_depth"):
        chiaro.render(s, whitted__max_dept=1)
    with pytest.raises(chiaro.SettingsError, match="available"):
        chiaro.render(s, "raytrace")
    assert "whitted.max_depth" in chiaro.settings_keys()
    assert set(chiaro.techniques()) >= {"preview", "flat", "gouraud", "phong", "whitted", "path"}


def test_region_equals_slice_of_full_render(root):
    s = chiaro.load(root / BOX)
    full = chiaro.render(s, "path", width=32, height=24, samples=2)
    tile = chiaro.render_region(s, 5, 3, 21, 17, "path", width=32, height=24, samples=2)
    assert tile.shape == (14, 16, 3)
    np.testing.assert_array_equal(tile, full[3:17, 5:21])
    with pytest.raises(ValueError, match="region"):
        chiaro.render_region(s, 0, 0, 40, 10, width=32, height=24)


def test_aovs_and_camera_override(root):
    s = chiaro.load(root / BOX)
    img = chiaro.render(s, "phong", width=16, height=16, aovs=True)
    assert img.depth.shape == (16, 16) and img.normal.shape == (16, 16, 3)
    assert np.isfinite(img.depth[8, 8]) and img.depth[8, 8] > 0
    cam = dict(s.camera)
    moved = chiaro.render(s, "phong", width=16, height=16, camera={"eye": [cam["eye"][0] + 100, cam["eye"][1], cam["eye"][2]]})
    assert not np.array_equal(moved, img)
    assert s.camera == cam, "a per-render camera must not change the scene"


def test_pickle_roundtrip(root):
    s = chiaro.load(root / BOX)
    t = pickle.loads(pickle.dumps(s))
    assert t.to_json() == s.to_json()
    np.testing.assert_array_equal(chiaro.render(t, "flat", width=16, height=16),
                                  chiaro.render(s, "flat", width=16, height=16))
    u = numpy_scene()
    assert chiaro.Scene.from_json(u.to_json()).to_json() == u.to_json()


def test_progress_callback_and_its_exception_cancels(root):
    s = chiaro.load(root / BOX)
    seen = []
    chiaro.render(s, "path", width=48, height=48, samples=4,
                  progress=lambda stage, done, total: seen.append((stage, done, total)))
    assert seen, "the callback is called at least once, at the end"
    stage, done, total = seen[-1]
    assert total > 0 and done == total, seen[-1]

    class Stop(Exception):
        pass

    def stop(stage, done, total):
        raise Stop()

    with pytest.raises(Stop):
        chiaro.render(s, "path", width=64, height=64, samples=64, progress=stop)


def test_ctrl_c_interrupts_a_render_cleanly(root):
    s = chiaro.load(root / BOX)
    seen = []
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            chiaro.render(s, "path", width=256, height=256, samples=512,
                          progress=lambda st, d, t: seen.append((d, t)))
    finally:
        timer.cancel()
    assert seen and seen[-1][0] < seen[-1][1], "the render stopped before finishing"
    # The module is still usable after the interrupt.
    assert chiaro.render(s, "flat", width=8, height=8).shape == (8, 8, 3)


def test_write_read_and_repr_png(tmp_path, root):
    img = chiaro.render(chiaro.load(root / BOX), "phong", width=16, height=12, aovs=True)
    png = img._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert img[0]._repr_png_() is None
    exr = tmp_path / "x.exr"
    chiaro.write(exr, img)
    np.testing.assert_array_equal(chiaro.read_image(exr), img)
    with pytest.raises(chiaro.SceneError, match="supported output formats"):
        chiaro.write(tmp_path / "x.gif", img)
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        chiaro.write(tmp_path / "y.png", np.zeros((4, 4)))


def test_metrics_are_those_of_compare(root):
    s = chiaro.load(root / BOX)
    flat = chiaro.render(s, "flat", width=16, height=16)
    phong = chiaro.render(s, "phong", width=16, height=16)
    m = chiaro.metrics(flat, phong)
    assert set(m) == {"relative_mse", "flip", "display_psnr", "rmse", "psnr",
                      "mean_relative_error"}
    assert m["relative_mse"] > 0 and 0 < m["flip"] < 1 and m["rmse"] > 0
    assert 5 < m["display_psnr"] < 60
    same = chiaro.metrics(phong, np.array(phong))
    assert same["relative_mse"] == 0 and same["rmse"] == 0 and same["flip"] < 1e-6
    assert same["psnr"] is None and same["display_psnr"] is None
    with pytest.raises(ValueError, match="shape"):
        chiaro.metrics(flat, phong[:8])


def test_compare_report(root, tmp_path):
    s = chiaro.load(root / BOX)
    report = chiaro.compare(s, ["flat", "phong"], reference="path:4", width=16, height=16,
                            name="box", cache_dir=tmp_path)
    assert report["scene"] == "box" and report["width"] == 16
    assert [t["technique"] for t in report["techniques"]] == ["flat", "phong"]
    for t in report["techniques"]:
        assert t["rmse"] > 0 and t["seconds"] >= 0
    assert report["reference"]["technique"] == "path" and report["reference"]["spp"] == 4
    # Four independent batches of one sample: the reference's noise is estimated.
    noise = report["reference"]["noise"]
    assert noise["batches"] == 4 and noise["relative_mse"] > 0
    assert noise["target_relative_mse"] is None
