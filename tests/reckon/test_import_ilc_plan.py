"""ILC floor plans across buildings (reckon/importers/ilc_plan.py) and the import's walkable report.

Crafted plans: small GeoJSON dicts built here, one per way of drawing a floor (type floor, a
'floor' property on the first feature, a containing polygon only, a MultiPolygon outline, an
outline with a hole, no outline, floor_info extents that differ from the outline's box), laid out
in metres and converted to longitude/latitude at 120 E 30 N as ILC's frame does. Real data: the
five floors of ../shared/data/pdr/ilc-site1-* (MIT), skipped when absent."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest

from hub.pedestrian.walkable import WalkableArea
from protocol.errors import InputError
from protocol.session_log import read_session
from reckon.cli import main
from reckon.importers.ilc_plan import read_floor_plan
from reckon.importers.report import WalkableCheck

LONGITUDE_DEG, LATITUDE_DEG = 120.0, 30.0
METRES_PER_DEGREE = math.radians(1.0) * 6_378_137.0
# every shop and room on ILC site 1 carries these (its label and the label's anchor, in Web Mercator)
SHOP = {"id": "5dd3d7732a57a34356595946", "name": "STARBUCKS", "display": "STARBUCKS",
        "category": ["5d35733bdb07255e495599ac"], "point": [13366730.06, 3541383.33], "points": []}
WHERE = "site/F1/geojson_map.json"


def lonlat(x_m: float, y_m: float) -> list[float]:
    return [LONGITUDE_DEG + x_m / (METRES_PER_DEGREE * math.cos(math.radians(LATITUDE_DEG))),
            LATITUDE_DEG + y_m / METRES_PER_DEGREE]


def box(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [lonlat(x0, y0), lonlat(x1, y0), lonlat(x1, y1), lonlat(x0, y1), lonlat(x0, y0)]


def feature(rings: list, properties: dict | None = None, kind: str = "Polygon") -> dict:
    return {"type": "Feature", "properties": properties or {}, "geometry": {"type": kind, "coordinates": rings}}


def shop(x0: float, y0: float, x1: float, y1: float, **extra) -> dict:
    return feature([box(x0, y0, x1, y1)], {**SHOP, **extra})


def plan_of(*features: dict) -> dict:
    return {"type": "FeatureCollection", "features": list(features)}


OUTLINE = box(0, 0, 100, 50)  # a 100 m x 50 m floor
WALL_SHOP = (10, 0, 30, 10)  # along the south wall, sharing its edge
INNER_SHOP = (60, 20, 80, 30)


def walkable(plan_polygons: list, *points: tuple[float, float]) -> list[bool]:
    area = WalkableArea.from_floor_plan(plan_polygons)
    return area.is_walkable(np.array([p[0] for p in points]), np.array([p[1] for p in points])).tolist()


def test_the_outline_by_its_type_floor_wherever_it_is():
    plan = read_floor_plan(plan_of(shop(*WALL_SHOP), feature([OUTLINE], {"type": "floor", "name": "F1"}),
                                   shop(*INNER_SHOP)), 100.0, 50.0, WHERE)
    assert (plan.rule, plan.outline) == ("type", (1,))
    assert plan.describe()[0] == "floor outline: feature 1, by its type 'floor' (1 part, 0 holes)"
    assert plan.describe()[1] == "shops and obstacles: 2 polygons, not walkable" and plan.warnings == ()
    (polygon,) = plan.polygons
    assert len(polygon) == 3  # the outline, then both shops as holes
    assert np.allclose(polygon[0][:4], [[0, 0], [100, 0], [100, 50], [0, 50]], atol=1e-6)
    assert plan.centre_lonlat == pytest.approx((lonlat(50, 25)[0], lonlat(50, 25)[1]))
    # shops are not walkable, the corridor is (the hub's area: 0.5 m tolerance at shop edges)
    assert walkable(plan.polygons, (20, 5), (70, 25), (50, 40), (5, 25)) == [False, False, True, True]


def test_the_outline_by_its_floor_property_without_a_type():
    """Another building of the set: feature 0 is the outline, {"floor": "F1", "center": [lon, lat]}
    and no type; its shops name the floor too, but carry a shop's keys."""
    plan = read_floor_plan(plan_of(feature([OUTLINE], {"floor": "F1", "center": lonlat(50, 25)}),
                                   shop(*WALL_SHOP, floor="F1"), shop(*INNER_SHOP, floor="F1")), 100.0, 50.0, WHERE)
    assert (plan.rule, plan.outline) == ("floor", (0,))
    assert plan.describe()[0] == "floor outline: feature 0, by its 'floor' property ('F1') (1 part, 0 holes)"
    assert len(plan.polygons[0]) == 3
    assert walkable(plan.polygons, (70, 25), (50, 40)) == [False, True]


def test_the_containing_polygon_when_nothing_names_the_floor():
    shops = [shop(5 + 9 * i, y, 12 + 9 * i, y + 8) for y in (2, 40) for i in range(10)]
    overhanging = shop(-4, 20, 3, 30)  # a shop along the west wall, its centroid outside the outline
    parking = feature([box(-300, -300, -120, -120)], {"name": "parking"})  # larger, outside: holds nothing
    plan = read_floor_plan(plan_of(*shops, overhanging, feature([OUTLINE], {"name": "mall"}), parking),
                           100.0, 50.0, WHERE)
    assert (plan.rule, plan.outline) == ("contains", (21,))  # the parking, larger, is passed over
    assert plan.describe()[0] == ("floor outline: feature 21, the largest polygon holding nearly all the others "
                                  "(20 of 22 centroids; 5,000 m^2) (1 part, 0 holes)")
    assert plan.left_out == (22,)  # the parking, wholly outside the outline
    assert plan.describe()[1] == ("shops and obstacles: 21 polygons, not walkable; left out, wholly outside the "
                                  "outline: feature 22")
    assert walkable(plan.polygons, (8, 44), (0, 25), (50, 25)) == [False, False, True]


def test_a_multipolygon_outline_in_two_wings():
    wings = feature([[box(0, 0, 40, 50)], [box(60, 0, 100, 50)]], {"type": "floor"}, kind="MultiPolygon")
    plan = read_floor_plan(plan_of(wings, shop(10, 10, 20, 20), shop(*INNER_SHOP)), 100.0, 50.0, WHERE)
    assert plan.describe()[0] == "floor outline: feature 0, by its type 'floor' (2 parts, 0 holes)"
    west, east = plan.polygons
    assert len(west) == 2 and len(east) == 2  # each shop a hole of the wing that holds it
    assert np.allclose(east[1][0], [60, 20], atol=1e-6)
    assert walkable(plan.polygons, (50, 25), (15, 15), (70, 25), (90, 40), (30, 40)) == [False, False, False,
                                                                                       True, True]


def test_an_outline_with_a_hole_is_not_walkable_there():
    courtyard = box(40, 20, 55, 30)
    plan = read_floor_plan(plan_of(feature([OUTLINE, courtyard], {"type": "floor"}), shop(*INNER_SHOP)),
                           100.0, 50.0, WHERE)
    assert plan.describe()[0] == "floor outline: feature 0, by its type 'floor' (1 part, 1 hole)"
    (polygon,) = plan.polygons
    assert len(polygon) == 3 and np.allclose(polygon[1][0], [40, 20], atol=1e-6)  # the courtyard, then the shop
    assert walkable(plan.polygons, (47, 25), (70, 25), (20, 40)) == [False, False, True]


def test_no_outline_is_refused_naming_the_file_the_rules_and_what_was_found():
    geojson = plan_of(shop(0, 0, 10, 10, type="room"), shop(20, 0, 30, 10, floor="F1"), shop(40, 0, 45, 10),
                      {"type": "Feature", "properties": {"type": "floor"}, "geometry": None})
    with pytest.raises(InputError) as caught:
        read_floor_plan(geojson, 100.0, 50.0, WHERE)
    message = str(caught.value)
    assert message.startswith(f"{WHERE}: no floor outline among its 4 features.")
    assert "(a) a polygon feature with properties.type 'floor': feature 3 has it but no polygon" in message
    assert ("(b) a polygon feature with a 'floor' property and none of a shop's keys (display, point, points): "
            "none; feature 1 has one but is a shop") in message
    assert ("(c) a polygon holding at least 90% of the other polygons' centroids: none; the largest, feature 0 "
            "(100 m^2), holds 0 of the other 2 (0%)") in message


def test_bad_geometry_names_the_file_and_feature():
    with pytest.raises(InputError, match=r"site/F1/geojson_map.json: feature 1: Polygon part 0 ring 0 is not"):
        read_floor_plan(plan_of(feature([OUTLINE], {"type": "floor"}), feature([[[1, 2], [3]]])), 100.0, 50.0, WHERE)
    with pytest.raises(InputError, match=r"site/F1/geojson_map.json: no Polygon or MultiPolygon feature among its 1"):
        read_floor_plan(plan_of({"type": "Feature", "properties": {"type": "floor"},
                                 "geometry": {"type": "Point", "coordinates": [1, 2]}}), 100.0, 50.0, WHERE)
    with pytest.raises(InputError, match=r"floor_info map size 0.0 x 50.0 m"):
        read_floor_plan(plan_of(feature([OUTLINE], {"type": "floor"})), 0.0, 50.0, WHERE)


def test_extents_that_fit_the_bounds_of_all_polygons_map_from_them():
    """floor_info made from every polygon (an entrance canopy drawn 10 m west of the outline):
    the outline's box is not the frame, and the outline starts 10 m east of x = 0."""
    canopy = shop(-10, 20, -2, 30)
    plan = read_floor_plan(plan_of(feature([OUTLINE], {"type": "floor"}), canopy), 110.0, 50.0, WHERE)
    assert np.allclose(plan.polygons[0][0][:3], [[10, 0], [110, 0], [110, 50]], atol=1e-6)
    assert plan.describe()[2].startswith("frame: the bounds of all polygons (") and plan.warnings == ()
    assert "(the outline's box, 100.0 x 50.0 m on the ground, fits floor_info less well)" in plan.describe()[2]
    assert plan.left_out == (1,)


def test_extents_that_fit_no_box_stretch_the_outline_and_warn():
    plan = read_floor_plan(plan_of(feature([OUTLINE], {"type": "floor"}), shop(*INNER_SHOP)), 200.0, 50.0, WHERE)
    assert np.allclose(plan.polygons[0][0][:3], [[0, 0], [200, 0], [200, 50]], atol=1e-6)
    assert np.allclose(plan.polygons[0][1][0], [120, 20], atol=1e-6)
    (warning,) = plan.warnings
    assert warning.startswith("floor_info's 200.0 x 50.0 m is not the outline's bounding box's 100.0 x 50.0 m "
                              "on the ground (x 2.000, y 1.000, more than 2% off)")
    assert f"warning: {warning}" in plan.describe()


def test_a_walkable_check_lists_what_is_outside_and_the_farthest():
    check = WalkableCheck(12, tuple((f"wp {n}", 0.1 * n) for n in range(1, 11)))
    assert str(check) == ("walkable: 2 of 12 waypoints inside; outside: wp 1 0.10 m, wp 2 0.20 m, wp 3 0.30 m, "
                          "wp 4 0.40 m, wp 5 0.50 m, wp 6 0.60 m, wp 7 0.70 m, wp 8 0.80 m, and 2 more; "
                          "farthest wp 10, 1.00 m")
    pooled = WalkableCheck.combine([("a", WalkableCheck(3)), ("b", WalkableCheck(2, (("wp 2", 4.5),)))])
    assert pooled.text("floor") == "floor: 4 of 5 waypoints inside; outside: b wp 2 4.50 m; farthest b wp 2, 4.50 m"
    assert str(WalkableCheck(3, problem="no area")) == "walkable: not checked (no area)"


def crafted_walk(waypoints: list[tuple[float, float]]) -> str:
    lines = ["#\tstartTime:1574559652119", "#\tSiteID:s2\tFloorName:F1", "#\tBrand:OPPO\tModel:PBCM10"]
    for time_ms in range(1574559652200, 1574559662200, 20):
        lines += [f"{time_ms}\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3", f"{time_ms}\tTYPE_GYROSCOPE\t0.0\t0.0\t0.01\t3"]
    lines += [f"{1574559652200 + 4000 * i}\tTYPE_WAYPOINT\t{x}\t{y}" for i, (x, y) in enumerate(waypoints)]
    return "".join(line + "\n" for line in lines)


def test_a_walk_on_a_floor_named_by_property_imports_and_reports_its_waypoints(tmp_path: Path, capsys):
    """The end to end case that was refused: the competition's layout, the outline only named by
    its 'floor' property; the second waypoint stands 5 m inside a shop."""
    floor = tmp_path / "site2" / "F1"
    (floor / "path_data_files").mkdir(parents=True)
    geojson = plan_of(feature([OUTLINE], {"floor": "F1", "center": lonlat(50, 25)}), shop(*INNER_SHOP, floor="F1"))
    (floor / "geojson_map.json").write_text(json.dumps(geojson))
    (floor / "floor_info.json").write_text(json.dumps({"map_info": {"width": 100.0, "height": 50.0}}))
    walk = floor / "path_data_files" / "walk1.txt.gz"
    walk.write_bytes(gzip.compress(crafted_walk([(50, 40), (70, 25), (90, 40)]).encode()))
    assert main(["import", "ilc", str(walk), "-o", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    venue = read_session(tmp_path / "out" / "walk1.mcap").session.venue
    outside_m = float(WalkableArea.from_venue(venue).outside_by_m(np.array([70.0]), np.array([25.0]))[0])
    assert 4.0 < outside_m < 5.0  # 5 m inside the shop, less the hub's tolerance at its edge
    assert f"  walkable: 2 of 3 waypoints inside; outside: wp 2 {outside_m:.2f} m; farthest wp 2" in printed
    assert f"floor {floor.resolve()} (1 walk):" in printed
    assert "  floor outline: feature 0, by its 'floor' property ('F1') (1 part, 0 holes)" in printed
    assert f"  walkable (the hub's area): 2 of 3 waypoints inside; outside: walk1 wp 2 {outside_m:.2f} m" in printed
    assert "  walkable with plan_tolerance_m 0: 2 of 3 waypoints inside; outside: walk1 wp 2 " in printed


def test_a_floor_without_an_outline_refuses_the_walk_naming_the_file(tmp_path: Path, capsys):
    floor = tmp_path / "site2" / "F1"
    (floor / "path_data_files").mkdir(parents=True)
    (floor / "geojson_map.json").write_text(json.dumps(plan_of(shop(0, 0, 10, 10), shop(20, 0, 30, 10))))
    (floor / "floor_info.json").write_text(json.dumps({"map_info": {"width": 30.0, "height": 10.0}}))
    walk = floor / "path_data_files" / "walk1.txt"
    walk.write_text(crafted_walk([(5, 5), (25, 5)]))
    assert main(["import", "ilc", str(walk), "-o", str(tmp_path / "walk1.mcap")]) == 2
    error = capsys.readouterr().err
    assert f"reckon: error: {floor.resolve() / 'geojson_map.json'}: no floor outline among its 2" in error
    assert not (tmp_path / "walk1.mcap").exists()


SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "pdr"
SITE1 = [SHARED / f"ilc-site1-{floor}" for floor in ("B1", "F1", "F2", "F3", "F4")]


@pytest.mark.parametrize("folder", SITE1, ids=lambda folder: folder.name)
def test_site1_outlines_are_found_by_their_type_and_every_shop_is_a_hole(folder: Path):
    if not (folder / "geojson_map.json").is_file():
        pytest.skip(f"shared ILC floor not found at {folder}")
    geojson = json.loads((folder / "geojson_map.json").read_text())
    size = json.loads((folder / "floor_info.json").read_text())["map_info"]
    plan = read_floor_plan(geojson, size["width"], size["height"], str(folder / "geojson_map.json"))
    assert (plan.rule, plan.outline, plan.left_out, plan.warnings) == ("type", (0,), (), ())
    shops = sum(len(f["geometry"]["coordinates"]) if f["geometry"]["type"] == "MultiPolygon" else 1
                for f in geojson["features"][1:])
    assert plan.obstacles == shops and sum(len(polygon) - 1 for polygon in plan.polygons) == shops
    assert plan.describe()[2].startswith("frame: the outline's bounding box (")
    corners = np.concatenate([np.array(polygon[0]) for polygon in plan.polygons])
    assert np.allclose(corners.min(axis=0), [0, 0])
    assert np.allclose(corners.max(axis=0), [size["width"], size["height"]])


def test_site1_f2_report_counts_the_waypoints_the_hubs_area_leaves_out(tmp_path: Path, capsys):
    folder = SITE1[2]
    walks = sorted((folder / "path_data_files").glob("*.txt.gz")) if folder.is_dir() else []
    if not walks:
        pytest.skip(f"shared ILC floor not found at {folder}")
    assert main(["import", "ilc", *map(str, walks), "-o", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    from reckon.importers.ilc_session import NO_TOLERANCE

    for settings, name in ((None, "walkable (the hub's area)"), (NO_TOLERANCE, "walkable with plan_tolerance_m 0")):
        checks = []
        for walk in walks:
            data = read_session(tmp_path / f"{walk.name.split('.')[0]}.mcap")
            area = (WalkableArea.from_venue(data.session.venue) if settings is None
                    else WalkableArea.from_venue(data.session.venue, settings))
            truth = data.truth["walker"]
            distances = area.outside_by_m(np.asarray(truth.x_m), np.asarray(truth.y_m))
            checks.append((walk.name.split(".")[0], WalkableCheck(len(distances), tuple(
                (f"wp {number}", float(d)) for number, d in enumerate(distances, start=1) if d > 0))))
        assert f"  {WalkableCheck.combine(checks).text(name)}\n" in printed + "\n"
        if settings is None:
            for walk_name, check in checks:
                assert f"{walk_name}.mcap: " in printed and f"  {check}" in printed
    assert (f"floor {folder.resolve()} (8 walks):\n"
            "  floor outline: feature 0, by its type 'floor' (2 parts, 0 holes)") in printed
