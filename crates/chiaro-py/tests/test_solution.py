"""Radiosity solutions from Python: solved once, rendered from without
solving (radiosity and hybrid, whole images and regions), round-tripped
through bytes and pickle, and refused for another scene."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import chiaro

BOX = "scenes/cornell-box.toml"
FAST = {"radiosity.solver": "hierarchical"}


@pytest.fixture(scope="module")
def box(root):
    return chiaro.load(root / BOX)


@pytest.fixture(scope="module")
def solution(box):
    return chiaro.solve_radiosity(box, settings=FAST)


@pytest.mark.parametrize("technique", ["radiosity", "hybrid"])
def test_render_from_a_solution_equals_the_solving_render(box, solution, technique):
    stages = []
    img = chiaro.render(box, technique, width=48, height=48, settings=FAST, solution=solution,
                        progress=lambda stage, done, total: stages.append(stage))
    assert stages and not any(s.startswith("radiosity") and s != "radiosity display" for s in stages), stages
    local = chiaro.render(box, technique, width=48, height=48, settings=FAST)
    np.testing.assert_array_equal(img, local)
    assert float(np.asarray(img).max()) > 0.0
    region = chiaro.render_region(box, 9, 5, 31, 40, technique, width=48, height=48,
                                  settings=FAST, solution=solution)
    np.testing.assert_array_equal(region, local[5:40, 9:31])
    assert region.stats["cropped"]


def test_a_solution_round_trips_through_bytes_and_pickle(box, solution):
    assert solution.element_count > 0 and solution.stats["solver"] == "hierarchical"
    data = solution.to_bytes()
    again = chiaro.RadiositySolution.from_bytes(box, data)
    assert again.to_bytes() == data
    unpickled = pickle.loads(pickle.dumps(solution))
    np.testing.assert_array_equal(
        chiaro.render(box, "radiosity", width=24, height=24, solution=unpickled),
        chiaro.render(box, "radiosity", width=24, height=24, solution=solution),
    )


def test_a_solution_of_another_scene_is_refused(box, solution):
    other = box.copy()
    other.add_light("point", position=(278, 500, 278), intensity=1000)
    with pytest.raises(chiaro.RenderError, match="does not match this scene"):
        chiaro.RadiositySolution.from_bytes(other, solution.to_bytes())
    for technique in ("radiosity", "hybrid"):
        with pytest.raises(chiaro.RenderError, match="does not match this scene"):
            chiaro.render(other, technique, width=16, height=16, solution=solution)
    with pytest.raises(chiaro.RenderError, match="cannot read radiosity solution"):
        chiaro.RadiositySolution.from_bytes(box, b"not a solution")


def test_a_solution_needs_radiosity_or_hybrid(box, solution):
    with pytest.raises(chiaro.SettingsError, match="radiosity or hybrid"):
        chiaro.render(box, "phong", width=16, height=16, solution=solution)
