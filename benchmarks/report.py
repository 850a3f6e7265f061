"""Part runner and writer of the benchmark report: ``docs/benchmarks.md``, its plots under
``docs/benchmarks/`` and a headline summary ``out/benchmarks_summary.md`` (the numbers the
README's cost table quotes).

Every number in the files comes from the run that writes them (the paper's values are the
constants of ``tables.py``, quoted from ../shared/paper/BRIEF.md).
"""

from __future__ import annotations

import time
from pathlib import Path

from . import grouping, physics, pieces, scaling, sph, stability, startup, stress_models, tables
from .common import REPO, BenchContext, Section, load_average, machine_info, md_table, warm_up

#: The parts in report order: key -> (module, one-line help).
PARTS = {
    "tables": (tables, "Table 1 and Table 2 of the paper beside our runs"),
    "grouping": (grouping, "two- vs single-scale: boundary grouping n = 1, 2, 4, 8, time and error"),
    "sph": (sph, "SPH stress error against particle count and time (plain, corrected)"),
    "stress_models": (stress_models, "the three stress models (sph, halfspace, fem): error against time, scenes"),
    "scaling": (scaling, "ms per frame and peak memory from 1e3 to 1e6 physics particles"),
    "stability": (stability, "the hard cases of the dynamics and the fracture"),
    "pieces": (pieces, "broken pieces' render surfaces: closed, on their cracks, what a split costs"),
    "startup": (startup, "runs as a user runs them: a fresh process, the cache written, start to exit"),
    "physics": (physics, "the automatic fracture model against experiments: star cracks, drop height, "
                         "fragment masses"),
}
#: Parts that write their own page under ``docs/benchmarks/`` (``taichi-frac bench
#: <part> --out docs``), which the report links to rather than repeats: two copies of one
#: measurement made at different commits would disagree.
OWN_PAGE = ("pieces", "startup", "physics")

#: The parts ``taichi-frac bench report`` runs by default.
REPORT_PARTS = tuple(k for k in PARTS if k not in OWN_PAGE)

#: Parts that need the report's World (and its warm-up).
NEEDS_WORLD = ("tables", "grouping", "stability", "pieces", "stress_models")


def run_parts(ctx: BenchContext, keys) -> list[Section]:
    if any(k in NEEDS_WORLD for k in keys):
        warm_up(ctx)
    sections = []
    for key in keys:
        ctx.progress(f"== {key}: {PARTS[key][1]}")
        sections.append(PARTS[key][0].run(ctx))
    return sections


def header(ctx: BenchContext, started: str, seconds: float, load_start: str) -> str:
    m = machine_info()
    memory = f"{m['memory_gb']:.0f} GB" if m["memory_gb"] else "unknown"
    lines = [
        "# Benchmarks",
        "",
    ]
    if ctx.quick:
        lines += ["> **QUICK SMOKE RUN** (`taichi-frac bench report --quick`): fewer frames, sizes and cases; "
                  "the numbers only show that the machinery works. The real report is "
                  "`taichi-frac bench report`.", ""]
    lines += [
        "Written by `taichi-frac bench report" + (" --quick" if ctx.quick else "") + "`; every number below comes "
        "from that run (the paper's values are quoted from `../shared/paper/BRIEF.md` section 4).",
        "",
        md_table(["", ""], [
            ["machine", f"{m['cpu']}, {m['cores']} cores, {memory} memory, {m['system']}"],
            ["software", f"Python {m['python']}, Taichi {m['taichi']} (arch {ctx.arch}), NumPy {m['numpy']}"],
            ["code", f"commit {m['commit']}"],
            ["started", started],
            ["took", f"{seconds / 60:.1f} min"],
            ["load average (1/5/15 min) at start / end", f"{load_start} — {load_average()}"],
        ], "ll"),
        "",
        "Times are wall clock on this machine's CPU; each part states what it ran.",
    ]
    return "\n".join(lines)


def write(ctx: BenchContext, sections: list[Section], markdown_path: Path, head: str,
          readme_part: Path | None) -> None:
    body = [head, "", "## Contents", ""]
    body += [f"{i}. [{s.title}](#{i}-{_anchor(s.title)})" for i, s in enumerate(sections, 1)]
    body += _separate_sections(markdown_path.parent / "benchmarks")
    for i, s in enumerate(sections, 1):
        # A section that also writes its own page under docs/benchmarks/ links from there
        # ("../guide/..."); here, one folder up, the same target is "guide/...".
        body += ["", f"## {i}. {s.title}", "", s.markdown.replace("](../", "](")]
    markdown_path.parent.mkdir(parents=True, exist_ok=True)
    markdown_path.write_text("\n".join(body) + "\n")
    ctx.progress(f"wrote {markdown_path}")
    if readme_part is not None:
        readme_part.write_text(readme_text(sections, markdown_path, readme_part))
        ctx.progress(f"wrote {readme_part}")


def _separate_sections(folder: Path) -> list[str]:
    """Links to the sections their own bench commands write (``docs/benchmarks/<part>.md``:
    meshes, contact, piece geometry, stress models, sweeps), each titled by its first heading."""
    pages = sorted(folder.glob("*.md"))
    if not pages:
        return []
    lines = ["", "Written by their own commands (`taichi-frac bench <part>`), at their own commits:", ""]
    for page in pages:
        title = next((t.lstrip("# ").strip() for t in page.read_text().splitlines() if t.startswith("#")), page.stem)
        lines.append(f"- [{title}]({folder.name}/{page.name})")
    return lines


def _anchor(title: str) -> str:
    keep = "".join(c for c in title.lower() if c.isalnum() or c in " -")
    return keep.replace(" ", "-")


def readme_text(sections: list[Section], markdown_path: Path, readme_part: Path) -> str:
    """The README's benchmark section: headline numbers of this run and a link to the report."""
    import os

    by_key = {s.key: s for s in sections}
    link = os.path.relpath(markdown_path, REPO)
    m = machine_info()
    lines = [
        "## Benchmarks (`taichi-frac bench report`)",
        "",
        f"`taichi-frac bench report` runs every measurement below and writes [`{link}`]({link}) with its plots; "
        f"this section is generated by the same run ({m['date']}, {m['cpu']}, {m['cores']} cores, commit "
        f"{m['commit']}). Each part also runs alone: `taichi-frac bench tables|grouping|sph|scaling|stability`; "
        "`--quick` is a smoke version.",
        "",
    ]
    if "tables" in by_key:
        h = by_key["tables"].headline
        rows = [[label, f"{v['on']['mean']:.1f} / {v['on']['max']:.1f}", f"{v['off']['mean']:.1f} / "
                 f"{v['off']['max']:.1f}", v["fragments"]] for label, v in h.items() if isinstance(v, dict)
                and "on" in v]
        if rows:
            lines += ["Table 2, ms per 20 ms frame (average / maximum):", "",
                      md_table(["scene", "fracture on", "fracture off", "fragments"], rows), ""]
        variants = [row for row in h.get("variants", []) if row[1] != tables.SCENE_ROW]
        if variants:
            lines += ["The same scenes with other crack controls (fracture on):", "",
                      md_table(["scene", "crack controls", "fragments", "fracture events", "ms per frame"],
                               variants, "llrrr"), ""]
    if "grouping" in by_key:
        per_n = by_key["grouping"].headline["per_n"]
        lines += ["Boundary grouping n (13 rings, unbreakable; rest-height error of a dropped ring):", "",
                  md_table(["n", "ms/frame", "rest height error [mm]"],
                           [[n, f"{v['ms']:.1f}", f"{1e3 * v['rest_error']:+.1f}"] for n, v in per_n.items()]), ""]
    if "sph" in by_key and "lattice" in by_key["sph"].headline:
        lat = by_key["sph"].headline["lattice"]
        lines += ["SPH stress error, interior, largest lattice block: " + "; ".join(
            f"{kind} {100 * err:.1f} % ({n:,} particles, {1e3 * t:.0f} ms)" for kind, (n, err, t) in lat.items()) + ".",
            ""]
    if "scaling" in by_key:
        h = by_key["scaling"].headline
        lines += [f"Scaling: ms per frame grows as particles^{h['slope_on']:.2f} with fracture on"
                  + (f" (^{h['slope_off']:.2f} with fracture off)" if h.get("slope_off") is not None else "")
                  + f"; {h['biggest_particles']:,} physics particles: {h['biggest_ms']:.0f} ms per frame over "
                  f"{h['frames']} frames, peak memory {h['biggest_mb']:,.0f} MB "
                  + ("(within 4 GB)." if h["fits"] else "(**over 4 GB**)."), ""]
    if "stability" in by_key:
        h = by_key["stability"].headline
        lines += [f"Stability: {h['passed']} of {h['total']} hard cases pass (no NaN, bounded speed and "
                  "penetration).", ""]
    return "\n".join(lines).rstrip() + "\n"


def run_report(quick: bool = False, out_dir: Path | None = None, parts=None, arch: str = "cpu",
               readme: bool | None = None) -> list[Section]:
    """Run the parts and write the report. Full run: ``docs/benchmarks.md``,
    ``docs/benchmarks/*.png`` and ``out/benchmarks_summary.md``; quick run: under
    ``out/bench_quick/`` (never over the real report)."""
    out_dir = Path(out_dir) if out_dir else (REPO / "out" / "bench_quick" if quick else REPO / "docs")
    markdown = out_dir / "benchmarks.md"
    ctx = BenchContext(quick=quick, markdown_dir=out_dir, figure_dir=out_dir / "benchmarks", arch=arch)
    started = time.strftime("%Y-%m-%d %H:%M %Z")
    load_start = load_average()
    t0 = time.perf_counter()
    keys = list(parts or REPORT_PARTS)
    sections = run_parts(ctx, keys)
    readme = (not quick and out_dir == REPO / "docs") if readme is None else readme
    readme_part = (REPO / "out" / "benchmarks_summary.md") if readme else (out_dir / "readme_benchmarks.md")
    readme_part.parent.mkdir(parents=True, exist_ok=True)
    write(ctx, sections, markdown, header(ctx, started, time.perf_counter() - t0, load_start), readme_part)
    for s in sections:
        print(f"\n## {s.title}\n\n{s.markdown}")
    return sections
