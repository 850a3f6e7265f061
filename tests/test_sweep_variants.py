"""Sweep bookkeeping without a cluster: variant specs, product and draws, stable ids, what
counts as a finished variant, the CSV's rows."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from taichi_frac.options import OptionError
from taichi_frac.scenes import apply_overrides
from taichi_frac.sweep import results
from taichi_frac.sweep.variants import format_value, make_variants, parse_vary, variant_id


def test_product_runs_every_combination_last_key_fastest():
    variants = make_variants(["ring.fracture.seed=0:3", "ring.fracture.crack_count=1,3,5"], scene_name="s.toml")
    expected = [(s, c) for s in range(3) for c in (1, 3, 5)]
    assert [(v.settings["ring.fracture.seed"], v.settings["ring.fracture.crack_count"]) for v in variants] == expected
    assert [v.index for v in variants] == list(range(9))
    assert len({v.id for v in variants}) == 9


def test_value_syntax():
    assert parse_vary("k=0:32").values == tuple(range(32))
    assert parse_vary("k=2:11:4").values == (2, 6, 10)
    assert parse_vary("k=2e6,6e6").values == (2e6, 6e6)
    assert parse_vary("k=[0,0,1],[0,0,2.5]").values == ([0, 0, 1], [0, 0, 2.5])
    assert parse_vary('k="porcelain",glass').values == ("porcelain", "glass")
    spec = parse_vary("k=2e6..6e6")
    assert (spec.values, spec.low, spec.high) == (None, 2e6, 6e6)
    for bad, words in (("k", "KEY=VALUES"), ("k=5:5", "empty"), ("k=0:1.5", "integer range"),
                       ("k=6..2", "low end"), ("k=1,,2", "empty value"), ("=1,2", "key")):
        with pytest.raises(OptionError, match=words):
            parse_vary(bad)


def test_values_round_trip_through_the_override_syntax():
    """A variant's overrides, read back by apply_overrides (what the worker does), give
    exactly its values (floats by repr: no digit lost)."""
    for value in (3, 0.1 + 0.2, 5772224.42228947, 1e-20, True, "glass", [0, 0, 1.5]):
        data = apply_overrides({"objects": [{"name": "ring"}]}, [f"ring.v={format_value(value)}"])
        assert data["objects"][0]["v"] == value


def test_samples_are_reproducible_and_inside_the_ranges():
    specs = ["ring.material.tensile_strength=2e6..6e6", "ring.fracture.seed=0:1000", "ring.fracture.crack_count=1,3,5"]
    a = make_variants(specs, scene_name="s.toml", samples=50, seed=7)
    b = make_variants(specs, scene_name="s.toml", samples=50, seed=7)
    c = make_variants(specs, scene_name="s.toml", samples=50, seed=8)
    assert [v.settings for v in a] == [v.settings for v in b] and [v.id for v in a] == [v.id for v in b]
    assert [v.settings for v in a] != [v.settings for v in c]
    strength = np.array([v.settings["ring.material.tensile_strength"] for v in a])
    assert np.all((strength >= 2e6) & (strength <= 6e6)) and strength.std() > 5e5
    assert {v.settings["ring.fracture.crack_count"] for v in a} == {1, 3, 5}
    assert all(isinstance(v.settings["ring.fracture.seed"], int) for v in a)
    with pytest.raises(OptionError, match="--samples"):
        make_variants(specs[:1], scene_name="s.toml")


def test_ids_are_stable_and_cover_everything_that_makes_the_run():
    settings = {"ring.fracture.seed": 3, "ring.fracture.crack_count": 5}
    base = variant_id(settings, scene_name="single_ring.toml", fixed=("simulation.duration=1",), frames=40)
    # A hand-written canonical form of the same run hashes to the same id.
    import hashlib

    canonical = ('{"fixed":["simulation.duration=1"],"frames":40,"scene":"single_ring.toml",'
                 '"settings":[["ring.fracture.seed","3"],["ring.fracture.crack_count","5"]]}')
    assert base == hashlib.sha256(canonical.encode()).hexdigest()[:12]
    others = [variant_id(dict(settings, **{"ring.fracture.seed": 4}), scene_name="single_ring.toml",
                         fixed=("simulation.duration=1",), frames=40),
              variant_id(settings, scene_name="single_ring.toml", fixed=(), frames=40),
              variant_id(settings, scene_name="single_ring.toml", fixed=("simulation.duration=1",), frames=41),
              variant_id(settings, scene_name="thirteen_rings.toml", fixed=("simulation.duration=1",), frames=40)]
    assert base not in others and len(set(others)) == 4


def _done_folder(tmp_path, vid="abc123abc123", scene_sha="s" * 64):
    folder = tmp_path / vid
    folder.mkdir()
    (folder / "cache.usdc").write_bytes(b"a complete cache")
    stats = dict(format=results.STATS_FORMAT, id=vid, status="done", scene_sha256=scene_sha, cache="cache.usdc",
                 cache_sha256=__import__("hashlib").sha256(b"a complete cache").hexdigest())
    results.write_json_atomic(folder / results.STATS_NAME, stats)
    return folder, stats


def test_only_a_complete_variant_counts_as_done(tmp_path):
    folder, stats = _done_folder(tmp_path)
    assert results.read_done(folder, stats["id"], "s" * 64) == stats
    assert results.read_done(folder, "another00000", "s" * 64) is None  # another variant's folder
    assert results.read_done(folder, stats["id"], "t" * 64) is None  # the scene file changed
    (folder / "cache.usdc").write_bytes(b"a cache cut short")  # a later run killed mid-write
    assert results.read_done(folder, stats["id"], "s" * 64) is None
    (folder / "cache.usdc").unlink()
    assert results.read_done(folder, stats["id"], "s" * 64) is None
    (folder / results.STATS_NAME).write_text('{"id": "abc1')  # torn stats
    assert results.read_done(folder, stats["id"], "s" * 64) is None


def test_csv_has_one_row_per_record_with_the_columns_in_order():
    records = [
        dict(id="a" * 12, status="done", settings={"k.seed": 1, "k.count": 3}, frames=10, fragments=4,
             fracture_events=1, mass_initial=2.0, mass_final=1.5, mass_dropped=0.5, ms_per_frame=3.25,
             wall_time=1.5, fragment_volumes=[1.0, 2.0, 3.0, 10.0], cache_sha256="f" * 64),
        dict(id="b" * 12, status="failed", settings={"k.seed": 2, "k.count": 3}, error="ValueError: bad"),
    ]
    rows = list(csv.DictReader(io.StringIO(results.csv_text(records, ["k.seed", "k.count"]))))
    assert [r["id"] for r in rows] == ["a" * 12, "b" * 12]
    first = rows[0]
    assert (first["k.seed"], first["k.count"], first["fragments"], first["mass_conserved"]) == ("1", "3", "4",
                                                                                                "1.000000000")
    assert float(first["volume_median_m3"]) == 2.5 and float(first["volume_max_m3"]) == 10.0
    assert float(first["volume_q25_m3"]) == 1.75  # numpy's linear quantile of 1, 2, 3, 10
    assert rows[1]["status"] == "failed" and rows[1]["error"] == "ValueError: bad" and rows[1]["fragments"] == ""
    header = next(csv.reader(io.StringIO(results.csv_text(records, ["k.seed", "k.count"]))))
    assert header == ["k.seed", "k.count"] + [name for name, _ in results.COLUMNS]
    json.dumps(records)  # records stay plain JSON
