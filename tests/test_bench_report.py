"""The benchmark report's machinery on tiny inputs (benchmarks/): the markdown tables
and PNG plots are written, and their numbers come from the run (particle counts equal the
models'), never typed in. No wall-clock time is asserted.

Runs on the World the whole test run shares (tests/support/dynamics.py), so no kernel
compiles for it beyond what the suite compiles anyway.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from benchmarks import grouping, report, scaling, sph, stability, tables
from benchmarks.common import BenchContext, Progress
from taichi_frac.options import FractureOptions, ParticleOptions
from taichi_frac.scenes import Collider, Scene, SceneObject, SimulationOptions
from support.dynamics import fresh_world

PNG = b"\x89PNG\r\n\x1a\n"


def tiny_ring_scene(group_size: int = 4, breakable: bool = True) -> Scene:
    ring = SceneObject(name="ring", primitive="torus:major=0.1,minor=0.025", breakable=breakable,
                       position=(0.0, 0.0, 0.15), euler_deg=(35.0, 10.0, 0.0), linear_velocity=(0.0, 0.0, -4.4),
                       particles=ParticleOptions(target_particles=300, boundary_group_size=group_size),
                       fracture=FractureOptions(impact_force_threshold=2000.0))
    return Scene(name="tiny_ring", objects=[ring], colliders=[Collider.ground()],
                 simulation=SimulationOptions(fps=50, duration=0.1, substeps=10))


@pytest.fixture(scope="module")
def ctx(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    return BenchContext(quick=True, markdown_dir=out, figure_dir=out / "benchmarks", progress=Progress(enabled=False),
                        world_instance=fresh_world())


def row_of(markdown: str, label: str) -> list[str]:
    line = next(line for line in markdown.splitlines() if line.startswith(f"| {label}"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_tables_report_the_models_counts_and_the_runs_frames(ctx):
    scene = tiny_ring_scene()
    model, _ = scene.objects[0].prepare()
    shifted = Scene(name="tiny_ring", objects=[dataclasses.replace(
        scene.objects[0], fracture=dataclasses.replace(scene.objects[0].fracture, seed=scene.objects[0].fracture.seed + 1))],
        colliders=scene.colliders, simulation=scene.simulation)
    case = tables.SceneCase("tiny ring", scene, timed=True, target_ms=1e6,
                            variants=((f"{tables.SCENE_ROW}, seeds + 1", shifted),))
    section = tables.run(ctx, cases=[case], frames=4)
    cells = row_of(section.markdown.split("**Table 2")[0], "tiny ring")
    assert cells[1:4] == [f"{model.tet_count:,}", f"{model.surface_particle_count:,}",
                          f"{model.boundary_particle_count:,}"]
    summary = section.headline["runs"]["tiny ring"]["on"][0]
    assert cells[4] == str(summary.fragments) and cells[5] == "4"
    table2 = row_of(section.markdown.split("**Table 2")[1], "tiny ring")
    assert table2[1] == f"{model.tet_count:,}"
    assert table2[2] == f"{model.boundary_particle_count:,} / {model.surface_particle_count:,}"
    assert table2[3] == f"{summary.ms_per_frame['mean']:.1f} / {summary.ms_per_frame['max']:.1f}"
    assert section.figures and section.figures[0].read_bytes().startswith(PNG)
    # The spread over seed sets: the scene's run and the shifted one, against the target.
    fragments = [row[2] for row in section.headline["variants"]]
    spread = row_of(section.markdown.split("The spread over seed sets")[1], "tiny ring")
    assert spread[1] == "2" and spread[4:] == ["1e+06", "yes"]
    assert spread[2] == f"{min(fragments)}-{max(fragments)} ({np.mean(fragments):.1f})"


def test_grouping_counts_collision_particles_per_n_and_measures_the_drop(ctx):
    section = grouping.run(ctx, group_sizes=(1, 4), frames=3, drop_particles=300, drop_seconds=0.6,
                           timing_scene=lambda n: tiny_ring_scene(n, breakable=False))
    for n in (1, 4):
        model, _ = tiny_ring_scene(n).objects[0].prepare()
        label = "1 (single-scale)" if n == 1 else "4"
        speed = row_of(section.markdown.split("**Error")[0], label)
        assert speed[1] == f"{model.boundary_particle_count:,}"
        drop = section.headline["drops"][n]
        assert drop.collision_particles == model.boundary_particle_count
        assert np.isfinite(drop.rest_height) and drop.first_impulse > 0.0
    # n = 1 is the single-scale layer: one collision sphere per surface particle.
    assert section.headline["drops"][1].collision_particles == tiny_ring_scene(1).objects[0].prepare()[0].surface_particle_count
    assert section.figures[0].read_bytes().startswith(PNG)


def test_sph_rows_come_from_the_block(ctx):
    section = sph.run(ctx, sizes=(8,), tet_targets=(), repeat=1, ring=False)
    rows = [r for r in section.headline["rows"]]
    assert [r[1] for r in rows] == [512, 512] and [r[3] for r in rows] == ["plain", "corrected"]
    assert row_of(section.markdown, "lattice")[1] == "512"
    assert all(0.0 < r[4]["far"] < 1.0 for r in rows)


def test_scaling_table_counts_and_slope(ctx):
    section = scaling.run(ctx, sizes=[(1, 200), (2, 200)], frames=2, fracture_off=False,
                          runner=scaling.in_process_runner(ctx))
    one, _ = scaling.ring_layout_scene(1, 200).objects[0].prepare()
    results = section.headline["results"][True]
    assert [r["physics_particles"] for r in results] == [one.tet_count, 2 * one.tet_count]
    assert f"| on | {2 * one.tet_count:,} |" in section.markdown
    p = np.array([r["physics_particles"] for r in results], float)
    ms = np.array([r["ms_mean"] for r in results])
    assert section.headline["slope_on"] == pytest.approx(np.log(ms[1] / ms[0]) / np.log(p[1] / p[0]))
    assert section.figures[0].read_bytes().startswith(PNG)


def test_fit_slope_recovers_a_power_law():
    p = np.array([1e3, 1e4, 1e5, 1e6])
    assert scaling.fit_slope(p, 3.0 * p ** 0.8) == pytest.approx(0.8)


def test_stability_rows_and_the_written_report(ctx, tmp_path):
    case = stability.case_single_tet(ctx, frames=5)
    assert case.passed and not case.nan and case.max_speed > 0.0
    section = stability.section([case], 0.0, 5)
    cells = row_of(section.markdown, "a body of a single tet")
    assert cells[1].startswith("pass") and cells[2] == f"{case.max_speed:.2f}" and cells[4] == "none"
    markdown, readme_part = tmp_path / "benchmarks.md", tmp_path / "readme_benchmarks.md"
    report.write(ctx, [section], markdown, report.header(ctx, "now", 1.0, "0 / 0 / 0"), readme_part)
    text = markdown.read_text()
    assert "QUICK SMOKE RUN" in text and "| a body of a single tet" in text
    assert re.search(r"1 of 1 hard cases pass", readme_part.read_text())


def test_report_links_the_pages_its_parts_write_themselves(ctx, tmp_path):
    """A part that writes its own page under docs/benchmarks/ (the piece geometry) is not
    run again by the report, whose copy would disagree with the page once the page is
    regenerated alone; the report links to the page instead."""
    assert "pieces" in report.PARTS and "pieces" not in report.REPORT_PARTS
    assert set(report.REPORT_PARTS) | set(report.OWN_PAGE) == set(report.PARTS)
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "piece-geometry.md").write_text("## Piece geometry\n\nmeasured\n")
    markdown = tmp_path / "benchmarks.md"
    report.write(ctx, [], markdown, "# Benchmarks", None)
    text = markdown.read_text()
    assert "- [Piece geometry](benchmarks/piece-geometry.md)" in text and "## 1." not in text
