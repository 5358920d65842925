"""A part's real shape in a plan (`geometry: {convex: ...}`): read, written back, and bounded on every door."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from opportune.formats import check_text
from opportune.formats.loader import plan_from_dict
from opportune.formats.shapes import THICKNESS
from opportune.limits import MAX_BODY_POINTS, MAX_SHAPE_BODIES, MAX_SHAPE_POINTS

CUBE = [[x, y, z] for x in (0, 0.02) for y in (0, 0.02) for z in (0, 0.02)]


def plan_text(geometry, parts: int = 1) -> str:
    return json.dumps({"parts": [{"id": f"p{i}", "geometry": geometry} for i in range(parts)]})


def problems(geometry, parts: int = 1):
    result = check_text(plan_text(geometry, parts), fmt="json", file="s.json")
    return [p for p in result.problems if p.severity == "error"]


def test_a_convex_shape_is_read_and_written_back():
    doc = {"parts": [{"id": "a", "geometry": {"convex": [CUBE, [[c + 0.02 if i == 0 else c for i, c in enumerate(p)]
                                                                for p in CUBE]]}}, "b"]}
    plan = plan_from_dict(doc)
    shape, bodies = plan.parts[0].geometry
    assert shape == "convex" and len(bodies) == 2 and bodies[0][1] == (0.0, 0.0, 0.02)
    assert plan_from_dict(plan.to_dict()).parts == plan.parts


@pytest.mark.parametrize("geometry, said", [
    ({"convex": [CUBE[:3]]}, "too few entries"),
    ({"convex": [CUBE + [[11, 0, 0]]]}, "above 10 m"),
    ({"convex": [[[0, 0]] + CUBE]}, "too few entries"),
    ({"convex": [CUBE] * (MAX_SHAPE_BODIES + 1)}, "too many entries"),
    ({"convex": [CUBE * (MAX_BODY_POINTS // 8 + 1)]}, "too many entries"),
    ({"convex": [[[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]]]}, "flat"),
    ({"convex": [[[x * 30, y, z] for x, y, z in CUBE]]}, "at most 0.5 m"),
    ({"convex": [[[x / 10, y / 10, z / 10] for x, y, z in CUBE]]}, "at least 0.005 m"),
    ({"convex": "cube"}, "not a convex shape"),
    ({"mesh": "cube.obj"}, "not a shape (box, cylinder or convex)"),
])
def test_a_bad_shape_is_refused_naming_where_and_what(geometry, said):
    found = problems(geometry)
    assert found and any(said in p.message for p in found), [p.message for p in found]
    assert all(p.code in ("geometry", "limit") for p in found)


def test_too_many_corners_in_all_are_refused_before_the_schema():
    bodies = [CUBE * (MAX_BODY_POINTS // 8)] * 2         # 512 corners a part
    parts = MAX_SHAPE_POINTS // 512 + 1
    found = problems({"convex": bodies}, parts)
    assert len(found) == 1 and found[0].code == "limit" and f"at most {MAX_SHAPE_POINTS:,}" in found[0].message
    assert not problems({"convex": bodies}, parts - 1)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 0.03), st.floats(0.001, 0.6))
def test_a_shape_is_accepted_exactly_within_its_bounds(thick, side):
    box = [[x, y, z] for x in (0, side) for y in (0, 0.01) for z in (0, thick)]
    ok = not problems({"convex": [box]})
    assert ok == (thick >= THICKNESS and 0.005 <= max(side, 0.01, thick) <= 0.5)


def test_the_service_takes_a_derived_plan_and_refuses_a_bad_shape(tmp_path):
    pytest.importorskip("fastapi")
    pytest.importorskip("trimesh")
    from contextlib import closing

    import yaml

    from opportune.derive import derive
    from opportune.service.testing import Client, ServiceProcess

    text = yaml.safe_dump(derive("geometry:pump").plan.to_dict())
    with ServiceProcess(tmp_path / "api.db", log=tmp_path / "api.log") as svc, \
            closing(Client(svc.url, svc.token(cell="cell-a"))) as client:     # closed: no socket left to the GC
        r = client.post("/plans", content=text, headers={"Content-Type": "application/yaml"}, key=False)
        assert r.status_code == 201, r.text
        flat = plan_text({"convex": [[[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]]]})
        r = client.post("/plans", content=flat, headers={"Content-Type": "application/json"}, key=False)
        assert r.status_code == 422 and "flat" in r.text
