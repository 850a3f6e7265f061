"""A sweep's results on disk: each variant's stats.json, and the sweep's sweep.json / sweep.csv.

``sweep.csv`` has one row per variant in sweep order; its columns are :data:`COLUMNS` (one
definition, used for the header and the rows) after one column per varied key. Timing
columns (``ms_per_frame``, ``wall_time_s``) are measurements and change from run to run;
every other column of a done variant is the same whenever and wherever (same machine and
arch) it ran: ``cache_sha256`` is the hash of the cache file, poses included.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

import numpy as np

STATS_NAME = "stats.json"
THUMBNAIL_NAME = "last_frame.png"
ERROR_NAME = "error.txt"
STATS_FORMAT = 1

#: Fragment volume quantiles in the CSV: (column, quantile).
VOLUME_QUANTILES = (("volume_min_m3", 0.0), ("volume_q25_m3", 0.25), ("volume_median_m3", 0.5),
                    ("volume_q75_m3", 0.75), ("volume_max_m3", 1.0))


def _quantile(q):
    def get(r):
        v = r.get("fragment_volumes")
        return f"{float(np.quantile(v, q)):.6g}" if v else ""
    return get


def _number(key, fmt):
    def get(r):
        v = r.get(key)
        return "" if v is None else format(v, fmt)
    return get


def _mass_conserved(r):
    """(final + dropped) / initial mass: 1 when fracture lost no mass."""
    if r.get("mass_initial"):
        return f"{(r['mass_final'] + r['mass_dropped']) / r['mass_initial']:.9f}"
    return ""


#: The CSV's columns after the varied keys: (name, record -> text).
COLUMNS = (
    ("id", lambda r: r["id"]),
    ("status", lambda r: r["status"]),
    ("frames", _number("frames", "d")),
    ("fragments", _number("fragments", "d")),
    ("fracture_events", _number("fracture_events", "d")),
    ("mass_conserved", _mass_conserved),
    ("ms_per_frame", _number("ms_per_frame", ".3f")),
    ("wall_time_s", _number("wall_time", ".3f")),
    *((name, _quantile(q)) for name, q in VOLUME_QUANTILES),
    ("cache_sha256", lambda r: r.get("cache_sha256", "")),
    ("error", lambda r: r.get("error", "")),
)
#: Columns that are measurements of time (they differ between two runs of one variant).
TIMING_COLUMNS = ("ms_per_frame", "wall_time_s")


def write_json_atomic(path: Path, data) -> None:
    """Write JSON through a temporary file and os.replace: a reader sees the old file or
    the whole new one, never a part."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "w") as fh:
        json.dump(data, fh, indent=1, default=_json_default)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON")


def read_done(folder: Path, variant_id: str, scene_sha256: str) -> dict | None:
    """The stats of a variant finished in ``folder``, or None when it must run (again):
    no stats, unreadable stats, another variant's or another scene file's stats, or a
    cache that is missing or not the one the stats were written for (a run cut short
    after the stats were written by an earlier run never gets here: the worker deletes
    the stats before it starts)."""
    from .worker import file_sha256

    path = Path(folder) / STATS_NAME
    try:
        stats = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if (not isinstance(stats, dict) or stats.get("format") != STATS_FORMAT or stats.get("status") != "done"
            or stats.get("id") != variant_id or stats.get("scene_sha256") != scene_sha256):
        return None
    cache = Path(folder) / str(stats.get("cache", ""))
    try:
        if not cache.is_file() or file_sha256(cache) != stats.get("cache_sha256"):
            return None
    except OSError:
        return None
    return stats


def csv_text(records: list[dict], keys: list[str]) -> str:
    """sweep.csv: a header, then one row per record (in the order given)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(list(keys) + [name for name, _ in COLUMNS])
    for r in records:
        settings = r.get("settings", {})
        writer.writerow([_setting_text(settings.get(k)) for k in keys] + [get(r) for _, get in COLUMNS])
    return out.getvalue()


def _setting_text(value) -> str:
    from .variants import format_value

    if value is None:
        return ""
    return value if isinstance(value, str) else format_value(value)


def write_results(directory: Path, records: list[dict], keys: list[str], meta: dict) -> None:
    """DIR/sweep.json (the sweep's settings and every variant's record, big per-run data
    left in the variants' stats.json) and DIR/sweep.csv, both written atomically."""
    directory = Path(directory)
    light = [{k: v for k, v in r.items() if k not in ("summary", "fragment_volumes", "traceback")} for r in records]
    for r, full in zip(light, records):
        if full.get("fragment_volumes"):
            r["volume_quantiles_m3"] = {name: float(np.quantile(full["fragment_volumes"], q))
                                        for name, q in VOLUME_QUANTILES}
    write_json_atomic(directory / "sweep.json", dict(meta, variants=light))
    tmp = directory / f".sweep.csv.tmp{os.getpid()}"
    tmp.write_text(csv_text(records, keys))
    os.replace(tmp, directory / "sweep.csv")
