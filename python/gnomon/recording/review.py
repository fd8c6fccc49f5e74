"""Reading Gnomon's rerun recordings back: summary, point export, cloud comparison.

Recordings are read with rerun's own chunk API (:class:`rerun.chunk.RrdReader`:
the recording store's chunks as Arrow record batches); nothing here parses the
``.rrd`` format. The entity layout is the one written by
:mod:`gnomon.recording.recorder`.

* :func:`summarize` — entities (with row counts), timeline ranges, point
  count, stored frames, metrics, warnings.
* :func:`read_points` / :func:`export_points` — the final cloud
  (``world/points``) as arrays / as a binary PLY whose x y z are bit-for-bit
  the float32 values that were logged (so equal to the run's ``points.ply``).
* :func:`compare` — distances from each point of one recording's cloud to its
  nearest neighbour in another's (exact nearest neighbours: a single k-d tree
  from OpenCV's FLANN searched without a check limit; distances recomputed in
  float64).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from gnomon.errors import GnomonError
from gnomon.outputs.ply import units_comment, write_points_ply
from gnomon.recording.recorder import ENTITY

__all__ = [
    "RecordingSummary",
    "TimelineRange",
    "summarize",
    "read_points",
    "export_points",
    "compare",
    "nearest_distances",
]

_POINTS = "/" + ENTITY["points"]


@dataclass
class TimelineRange:
    """One timeline's extent. ``start``/``end`` are ints (sequence) or ISO-8601 UTC strings."""

    name: str
    kind: str  # "sequence" | "timestamp" | "duration"
    start: int | str
    end: int | str
    rows: int


@dataclass
class RecordingSummary:
    path: str
    application_id: str
    recording_id: str
    recording_name: str | None
    entities: dict[str, int]  # entity path → number of rows logged
    timelines: dict[str, TimelineRange]
    point_count: int | None
    frames_stored: int
    metrics: dict[str, float]
    warnings: list[dict[str, Any]] = field(default_factory=list)
    units: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def format(self) -> str:
        """A human-readable multi-line summary."""
        lines = [
            f"recording  {self.path}",
            f"name       {self.recording_name or '-'}  (application {self.application_id}, id {self.recording_id})",
        ]
        if self.timelines:
            lines.append("timelines")
            for t in self.timelines.values():
                lines.append(f"  {t.name:<13} {t.kind:<9} {t.start} .. {t.end}  ({t.rows} rows)")
        lines.append(
            "points     " + ("none" if self.point_count is None else f"{self.point_count}")
            + (f" ({self.units})" if self.units else "")
        )
        lines.append(f"frames     {self.frames_stored} stored (images, or references into the input video)")
        lines.append("entities")
        for path, rows in self.entities.items():
            lines.append(f"  {path}  ({rows} rows)")
        if self.metrics:
            lines.append("metrics")
            for k, v in self.metrics.items():
                lines.append(f"  {k} = {v:.6g}")
        lines.append(f"warnings   {len(self.warnings)}")
        for w in self.warnings:
            where = f"frame {w['frame']}: " if w.get("frame") is not None else ""
            lines.append(f"  [{w.get('level') or 'WARN'}] {where}{w['text']}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- reading


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _reader(path: str | Path):
    from rerun.chunk import RrdReader

    p = Path(path)
    if not p.exists():
        raise GnomonError(f"{p}: no such file")
    if p.is_dir():
        raise GnomonError(f"{p}: is a directory, not a rerun recording (.rrd)")
    try:
        reader = RrdReader(p)
        stores = reader.recordings()
    except (RuntimeError, ValueError, OSError) as exc:
        raise GnomonError(f"{p}: not a readable rerun recording (.rrd): {_one_line(exc)}") from None
    if not stores:
        raise GnomonError(f"{p}: the file holds no rerun recording")
    return reader, stores[0]


def _chunks(path: str | Path, content: str | None = None) -> Iterator[Any]:
    reader, store = _reader(path)
    stream = reader.stream(store=store)
    if content is not None:
        stream = stream.filter(content=content)
    try:
        yield from stream
    except (RuntimeError, ValueError, OSError) as exc:
        raise GnomonError(f"{path}: cannot read the recording: {_one_line(exc)}") from None


def _component_columns(batch) -> dict[str, int]:
    """component identifier (e.g. 'Points3D:positions') → column index."""
    out = {}
    for i, f in enumerate(batch.schema):
        md = f.metadata or {}
        if md.get(b"rerun:kind") == b"data":
            out[md.get(b"rerun:component", f.name.encode()).decode()] = i
    return out


def _index_columns(batch) -> dict[str, int]:
    out = {}
    for i, f in enumerate(batch.schema):
        md = f.metadata or {}
        if md.get(b"rerun:kind") == b"index":
            out[md.get(b"rerun:index_name", f.name.encode()).decode()] = i
    return out


def _cell(column, row: int):
    """The values of one list cell, flattened to a flat Arrow array (None if null)."""
    if not column[row].is_valid:
        return None
    return column.slice(row, 1).flatten()


def _cell_numpy(column, row: int, width: int | None = None) -> np.ndarray | None:
    values = _cell(column, row)
    if values is None:
        return None
    import pyarrow as pa

    while pa.types.is_fixed_size_list(values.type) or pa.types.is_list(values.type):
        values = values.flatten()
    arr = values.to_numpy(zero_copy_only=False)
    return arr.reshape(-1, width) if width else arr


def _cell_str(column, row: int) -> str | None:
    values = _cell(column, row)
    if values is None or len(values) == 0:
        return None
    return str(values[0].as_py())


def _latest(path: str | Path, entity: str, components: list[str]) -> dict[str, tuple[Any, int]]:
    """For each component, the (column, row) of its last logged non-null value on ``entity``."""
    found: dict[str, tuple[Any, int]] = {}
    for chunk in _chunks(path, content=entity):
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        cols = _component_columns(batch)
        for comp in components:
            if comp in cols:
                col = batch.column(cols[comp])
                valid = np.flatnonzero(~np.asarray(col.is_null().to_pylist(), dtype=bool))
                if valid.size:
                    found[comp] = (col, int(valid[-1]))
    return found


def read_points(path: str | Path, entity: str = ENTITY["points"]) -> dict[str, Any]:
    """The cloud logged at ``entity``: ``xyz`` float32 (N, 3), ``rgb`` uint8 (N, 3) | None,
    ``sigma`` float32 (N,) | None, ``uv`` float32 (N, 2) | None, ``units`` str | None."""
    ent = "/" + entity.strip("/")
    comps = ["Points3D:positions", "Points3D:colors", "GnomonPoints:sigma", "GnomonPoints:uv", "GnomonPoints:units"]
    found = _latest(path, ent, comps)
    if "Points3D:positions" not in found:
        raise GnomonError(f"{path}: the recording has no point cloud at {ent}")
    xyz = _cell_numpy(*found["Points3D:positions"], width=3)
    assert xyz is not None
    xyz = np.ascontiguousarray(xyz, dtype=np.float32)
    n = len(xyz)
    out: dict[str, Any] = {"xyz": xyz, "rgb": None, "sigma": None, "uv": None, "units": None}
    if "Points3D:colors" in found:
        packed = _cell_numpy(*found["Points3D:colors"])
        if packed is not None and len(packed) == n:
            packed = packed.astype(np.uint32)
            out["rgb"] = np.stack([(packed >> 24) & 0xFF, (packed >> 16) & 0xFF, (packed >> 8) & 0xFF], axis=1).astype(
                np.uint8
            )
    if "GnomonPoints:sigma" in found:
        s = _cell_numpy(*found["GnomonPoints:sigma"])
        if s is not None and len(s) == n:
            out["sigma"] = np.ascontiguousarray(s, dtype=np.float32)
    if "GnomonPoints:uv" in found:
        uv = _cell_numpy(*found["GnomonPoints:uv"])
        if uv is not None and uv.size == 2 * n:
            out["uv"] = np.ascontiguousarray(uv.reshape(n, 2), dtype=np.float32)
    if "GnomonPoints:units" in found:
        out["units"] = _cell_str(*found["GnomonPoints:units"])
    return out


def export_points(path: str | Path, out_ply: str | Path, entity: str = ENTITY["points"]) -> int:
    """Write the recording's cloud to a binary PLY (as ``points.ply``); returns the point count."""
    pts = read_points(path, entity)
    comments = [f"exported by gnomon review from {Path(path).name}"]
    if pts["units"]:
        comments.append(units_comment(pts["units"]))
    write_points_ply(out_ply, pts["xyz"], pts["rgb"], pts["sigma"], pts["uv"], comments)
    return len(pts["xyz"])


def _time_value(value: Any, kind: str) -> int | str:
    if kind == "timestamp":
        ns = int(value)
        dt = datetime.fromtimestamp(ns // 1_000_000_000, tz=UTC)
        frac = ns % 1_000_000_000
        text = dt.strftime("%Y-%m-%dT%H:%M:%S")
        return text + (f".{frac:09d}".rstrip("0") if frac else "") + "Z"
    return int(value)


def summarize(path: str | Path) -> RecordingSummary:
    """Summarise a recording (see :class:`RecordingSummary`)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    reader, store = _reader(path)
    entities: dict[str, int] = {}
    ranges: dict[str, list] = {}  # name → [kind, min, max, rows]
    name: str | None = None
    metrics: dict[str, float] = {}
    warnings: list[tuple[int, dict[str, Any]]] = []
    frames_stored = 0
    for chunk in _chunks(path):
        ent = chunk.entity_path
        batch = chunk.to_record_batch()
        comps = _component_columns(batch)
        if ent == "/__properties":
            if "RecordingInfo:name" in comps:
                col = batch.column(comps["RecordingInfo:name"])
                for row in range(batch.num_rows):
                    name = _cell_str(col, row) or name
            continue
        entities[ent] = entities.get(ent, 0) + batch.num_rows
        idx = _index_columns(batch)
        for tl, i in idx.items():
            col = batch.column(i)
            if col.null_count == len(col):
                continue
            t = col.type
            kind = "timestamp" if pa.types.is_timestamp(t) else "duration" if pa.types.is_duration(t) else "sequence"
            ints = col.cast(pa.int64())
            lo, hi = pc.min(ints).as_py(), pc.max(ints).as_py()
            rows = len(col) - col.null_count
            if tl in ranges:
                span = ranges[tl]
                span[1], span[2], span[3] = min(span[1], lo), max(span[2], hi), span[3] + rows
            else:
                ranges[tl] = [kind, lo, hi, rows]
        if ent == "/" + ENTITY["image"] and "EncodedImage:blob" in comps:
            frames_stored += batch.num_rows - batch.column(comps["EncodedImage:blob"]).null_count
        if ent == "/" + ENTITY["image"] and "VideoFrameReference:timestamp" in comps:  # a video input
            frames_stored += batch.num_rows - batch.column(comps["VideoFrameReference:timestamp"]).null_count
        if ent.startswith("/" + ENTITY["metrics"] + "/") and "Scalars:scalars" in comps:
            col = batch.column(comps["Scalars:scalars"])
            for r in range(batch.num_rows):
                v = _cell_numpy(col, r)
                if v is not None and v.size:
                    metrics[ent[len(ENTITY["metrics"]) + 2:]] = float(v[-1])
        if ent == "/" + ENTITY["log"] and "TextLog:text" in comps:
            text_col = batch.column(comps["TextLog:text"])
            level_col = batch.column(comps["TextLog:level"]) if "TextLog:level" in comps else None
            frame_col = batch.column(idx["frame"]).to_pylist() if "frame" in idx else None
            order_col = batch.column(idx["log_time"]).cast(pa.int64()).to_pylist() if "log_time" in idx else None
            for r in range(batch.num_rows):
                text = _cell_str(text_col, r)
                if text is None:
                    continue
                warnings.append(
                    (
                        order_col[r] if order_col and order_col[r] is not None else 0,
                        {
                            "text": text,
                            "level": _cell_str(level_col, r) if level_col is not None else None,
                            "frame": frame_col[r] if frame_col else None,
                        },
                    )
                )
    points = None
    units = None
    if "/" + ENTITY["points"] in entities:
        try:
            pts = read_points(path)
            points, units = len(pts["xyz"]), pts["units"]
        except GnomonError:
            points = None
    timelines = {
        tl: TimelineRange(tl, kind, _time_value(lo, kind), _time_value(hi, kind), rows)
        for tl, (kind, lo, hi, rows) in sorted(ranges.items())
    }
    warnings.sort(key=lambda x: x[0])
    return RecordingSummary(
        path=str(path),
        application_id=store.application_id,
        recording_id=store.recording_id,
        recording_name=name,
        entities=dict(sorted(entities.items())),
        timelines=timelines,
        point_count=points,
        frames_stored=frames_stored,
        metrics=dict(sorted(metrics.items())),
        warnings=[w for _, w in warnings],
        units=units,
    )


# --------------------------------------------------------------------------- comparing


def nearest_distances(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point of ``a`` (N, 3), the distance to its nearest point in ``b`` (M, 3) and its index.

    Exact: one k-d tree (FLANN ``KDTREE_SINGLE``) over ``b`` searched with no
    check limit, on coordinates centred at b's mean so that float32 keeps its
    precision far from the origin; distances are then recomputed in float64.
    """
    import cv2

    a64 = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    b64 = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if len(b64) == 0:
        raise ValueError("nearest_distances: empty reference cloud")
    if len(a64) == 0:
        return np.empty(0), np.empty(0, dtype=np.int64)
    origin = b64.mean(axis=0)
    bf = np.ascontiguousarray(b64 - origin, dtype=np.float32)
    af = np.ascontiguousarray(a64 - origin, dtype=np.float32)
    # 4 = FLANN_INDEX_KDTREE_SINGLE. flann_Index is in cv2 but missing from its type stubs.
    index = cv2.flann_Index(bf, dict(algorithm=4, leaf_max_size=10))  # type: ignore[attr-defined]
    nn, _ = index.knnSearch(af, 1, params=dict(checks=-1))  # -1 = unlimited: exact search
    nn = nn.reshape(-1).astype(np.int64)
    d = np.linalg.norm(a64 - b64[nn], axis=1)
    return d, nn


def compare(path_a: str | Path, path_b: str | Path, entity: str = ENTITY["points"]) -> dict[str, Any]:
    """Distances from recording a's cloud to recording b's (nearest neighbour per point of a).

    Returns count (points of a), count_b, mean, median, p95, max, rms (in the
    clouds' units) and units.
    """
    pa_ = read_points(path_a, entity)
    pb_ = read_points(path_b, entity)
    if len(pb_["xyz"]) == 0:
        raise GnomonError(f"{path_b}: the point cloud is empty")
    if len(pa_["xyz"]) == 0:
        raise GnomonError(f"{path_a}: the point cloud is empty")
    if pa_["units"] and pb_["units"] and pa_["units"] != pb_["units"]:
        raise GnomonError(f"{path_a} is in {pa_['units']} but {path_b} is in {pb_['units']}")
    d, _ = nearest_distances(pa_["xyz"], pb_["xyz"])
    return {
        "a": str(path_a),
        "b": str(path_b),
        "count": int(len(d)),
        "count_b": int(len(pb_["xyz"])),
        "mean": float(d.mean()),
        "median": float(np.median(d)),
        "p95": float(np.percentile(d, 95)),
        "max": float(d.max()),
        "rms": float(np.sqrt(np.mean(d * d))),
        "units": pa_["units"] or pb_["units"],
    }


def format_compare(result: dict[str, Any]) -> str:
    u = f" {result['units']}" if result.get("units") else ""
    return (
        f"compare    {result['a']} → {result['b']}\n"
        f"  points   {result['count']} → {result['count_b']}\n"
        f"  distance mean {result['mean']:.6g}{u}, median {result['median']:.6g}{u}, "
        f"p95 {result['p95']:.6g}{u}, max {result['max']:.6g}{u}, rms {result['rms']:.6g}{u}"
    )


def to_json(obj: Any) -> str:
    return json.dumps(obj, indent=2, ensure_ascii=False)
