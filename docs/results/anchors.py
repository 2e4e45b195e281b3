"""Measure the published ray-reordering findings of ``anchors.toml`` and write ``anchors.md``.

``python docs/results/anchors.py run --work DIR [--size N] [--only ID ...]``
    measures each anchor on a path-traced trace of the data file's scene at
    ``N`` x ``N`` pixels and writes ``DIR/anchors.json``: per anchor the
    values at each level, the misses per ray behind them and the command that
    reproduces it, with the commit, machine, date and wall time.
``python docs/results/anchors.py page --work DIR [DIR ...]``
    stores the records of those runs (one per image size) beside this
    script as ``anchors.json`` and writes ``anchors.md`` from them and the
    data file: the first run in full, the others as a verdict table each;
    ``page`` without ``--work`` rewrites the page from the stored records.

What each quantity is and how a rule decides "confirmed" is stated at the top
of ``anchors.toml``. An anchor whose order is not registered in
:data:`coherence.ray_orders.RAY_ORDERS` at the commit run is "not measured",
with the reason.
"""
from __future__ import annotations

import argparse
import json
import operator
import shlex
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))
from generate import git_commit, machine  # noqa: E402
from pages import STAMP_PREFIX, markdown_table  # noqa: E402

DATA = HERE / "anchors.toml"
MEASURES = ("bounce_ratio", "order_gain", "submission_change")
RULES = {">=": operator.ge, "<=": operator.le}
ANCHOR_FIELDS = ("id", "reference", "finding", "published", "citation", "claim", "measure", "order", "levels",
                 "rule", "threshold")
RUN_FIELDS = ("scene", "spp", "seed", "max_depth", "hierarchy", "layout", "submission_seed")
CONFIRMED, NOT_CONFIRMED, NOT_MEASURED = "confirmed", "not confirmed", "not measured"


def load_anchors(path: Path = DATA) -> tuple[dict, list[dict]]:
    """The run settings and the anchors of the data file, checked.

    Raises
    ------
    ValueError
        Naming the file, the anchor and the field that is missing or wrong.
    """
    with open(path, "rb") as handle:
        data = tomllib.load(handle)
    run = data.get("run", {})
    for field in RUN_FIELDS:
        if field not in run:
            raise ValueError(f"{path.name}: [run] needs {field!r}")
    anchors = data.get("anchor", [])
    seen = set()
    for number, anchor in enumerate(anchors, 1):
        where = f"{path.name}: anchor {anchor.get('id', number)!r}"
        for field in ANCHOR_FIELDS:
            if field not in anchor:
                raise ValueError(f"{where} needs {field!r}")
        if anchor["id"] in seen:
            raise ValueError(f"{where} repeats an id")
        seen.add(anchor["id"])
        if anchor["measure"] not in MEASURES:
            raise ValueError(f"{where}: measure must be one of {', '.join(MEASURES)}, got {anchor['measure']!r}")
        if anchor["rule"] not in RULES:
            raise ValueError(f"{where}: rule must be one of {', '.join(RULES)}, got {anchor['rule']!r}")
        if not anchor["levels"] or not all(isinstance(level, str) for level in anchor["levels"]):
            raise ValueError(f"{where}: levels must be a non-empty list of level names such as \"L2\"")
        if anchor["measure"] == "bounce_ratio" and "bounce" not in anchor:
            raise ValueError(f"{where}: bounce_ratio needs 'bounce'")
    if not anchors:
        raise ValueError(f"{path.name} holds no [[anchor]]")
    return run, anchors


def verdict(values: dict, rule: str, threshold: float) -> str:
    """``confirmed`` when every level's value satisfies ``value rule threshold``; ``not measured`` without values.

    Parameters
    ----------
    values : dict
        Level name -> measured value (None when not measured).
    """
    if not values or any(value is None for value in values.values()):
        return NOT_MEASURED
    holds = all(RULES[rule](float(value), float(threshold)) for value in values.values())
    return CONFIRMED if holds else NOT_CONFIRMED


def line_counts(records: np.ndarray, placed, line_size: int) -> np.ndarray:
    """Lines of ``line_size`` bytes each record spans (int64, (R,)), as ``placed.addresses`` lists them."""
    from tracer.trace.records import INDEX_MASK, KIND_SHIFT

    records = np.asarray(records, dtype=np.uint32)
    kinds = (records >> np.uint32(KIND_SHIFT)).astype(np.int64)
    rows = placed.kind_first[kinds] + (records & np.uint32(INDEX_MASK)).astype(np.int64)
    shift = line_size.bit_length() - 1
    start = placed.record_start[rows]
    return ((start + placed.record_size[rows] - 1) >> shift) - (start >> shift) + 1


def misses_by_segment(trace, placed, hierarchy) -> np.ndarray:
    """Misses of every segment at every level, the trace replayed as traced (depth-first) on empty caches.

    Returns
    -------
    ndarray of int64, shape (S, n_levels)
        An access misses level ``k`` when a level below ``k`` or memory
        served it; the columns sum to the replay's misses per level.
    """
    from cachesim import simulate

    line_size = min(level.line_size for level in hierarchy.levels)
    records = np.asarray(trace.records)
    addresses = placed.addresses(records, line_size)
    result = simulate(addresses, hierarchy, return_levels=True)
    ints = trace.segments.ints
    record_segment = np.repeat(np.arange(len(ints)), ints[:, 5] - ints[:, 4])
    access_segment = np.repeat(record_segment, line_counts(records, placed, line_size))
    n_levels = len(hierarchy.levels)
    out = np.zeros((len(ints), n_levels), dtype=np.int64)
    for level in range(n_levels):
        out[:, level] = np.bincount(access_segment, weights=result.served_by > level, minlength=len(ints))
    if not np.array_equal(out.sum(axis=0), np.asarray(result.misses, dtype=np.int64)):
        raise ValueError("misses per segment do not add up to the replay's misses: the record-to-line "
                         "counts disagree with the layout's addresses")
    return out


class Workload:
    """One path-traced trace of the data file's scene, placed, with its machine and tree."""

    def __init__(self, scene, trace, placed, hierarchy):
        self.scene, self.trace, self.placed, self.hierarchy = scene, trace, placed, hierarchy
        self._tree = None

    @classmethod
    def cached(cls, run: dict, size: int, max_depth: int) -> "Workload":
        """The data file's scene path-traced at ``size`` x ``size`` (from the trace cache), placed by its layout."""
        from analyses.traces import cached_trace
        from cachesim.config import get_hierarchy
        from coherence.layout import get_layout
        from coherence.studies import place_layout

        scene, trace, _ = cached_trace(run["scene"], size, workload="pathtrace", max_depth=max_depth,
                                       path_samples=(run["spp"], run["seed"]), progress=False)
        return cls(scene, trace, place_layout(get_layout(run["layout"]), trace, scene), get_hierarchy(run["hierarchy"]))

    @property
    def n_rays(self) -> int:
        return self.trace.segments.n_segments

    def level(self, name: str) -> int:
        names = [level.name for level in self.hierarchy.levels]
        if name not in names:
            raise ValueError(f"anchors.toml: level {name!r} is not a level of {names}")
        return names.index(name)

    def tree(self):
        """The trace's kd-tree, built again from the scene with the configuration the trace recorded."""
        if self._tree is None:
            from tracer.kd.tree import KdTreeConfig, build_kdtree

            from tracer.trace.records import RecordKind

            tree = build_kdtree(self.scene, KdTreeConfig(**self.trace.metadata["kd_config"]))
            first = self.placed.kind_first
            if len(tree.nodes) != first[RecordKind.KD_NODE + 1] - first[RecordKind.KD_NODE]:
                raise ValueError(f"the kd-tree built again has {len(tree.nodes)} nodes, the trace's "
                                 f"{first[RecordKind.KD_NODE + 1] - first[RecordKind.KD_NODE]}: not the trace's tree")
            self._tree = tree
        return self._tree

    def pixel_rows(self, pixel_order: np.ndarray) -> np.ndarray:
        """Segment rows with pixels in ``pixel_order``, each pixel's rows as traced."""
        pixels = self.trace.segments.ints[:, 0]
        starts = np.searchsorted(pixels, pixel_order, side="left")
        stops = np.searchsorted(pixels, pixel_order, side="right")
        return np.concatenate([np.arange(a, b) for a, b in zip(starts, stops)]).astype(np.int64)

    def recipe(self, order: str):
        """The order named in :data:`coherence.ray_orders.RAY_ORDERS`; the treelet queues keep their
        registered treelet size with this layout's kd-node bytes."""
        from coherence.ray_orders import RAY_ORDERS
        from tracer.trace.records import RecordKind

        if order not in RAY_ORDERS:
            raise ValueError(f"anchors.toml: unknown ray order {order!r}")
        chosen = RAY_ORDERS[order]
        if order != "treelet":
            return chosen
        node_bytes = int(self.placed.record_size[self.placed.kind_first[RecordKind.KD_NODE]])
        return chosen.sized(chosen.treelet_bytes, node_bytes)

    def order_misses(self, order: str, rows: np.ndarray, own_records: bool = True) -> np.ndarray:
        """Misses per level (int64, (n_levels,)) of one process tracing ``rows`` in ``order``.

        ``own_records=False`` replays the order's pieces without its ray-state
        and queue records: what the order would give if its buffers were free.
        """
        from coherence.ray_order_base import OrderedPieces
        from coherence.ray_orders import order_pieces, replay_order

        recipe = self.recipe(order)
        tree = self.tree() if getattr(recipe, "needs_tree", False) else None
        records = self.trace.records if getattr(recipe, "needs_records", False) else None
        pieces = order_pieces(self.trace.segments, rows, recipe, tree=tree, records=records)
        if not own_records:
            pieces = OrderedPieces(pieces.piece_first, pieces.piece_stop, pieces.piece_segment,
                                   pieces.aux_records[:0], pieces.aux_after[:0], pieces.sort_cycles)
        # the order's ray states and queue entries sit in its own buffers (OrderBuffers' default addresses)
        misses = replay_order(self.trace.records, pieces, self.placed, self.hierarchy).misses
        return np.asarray(misses, dtype=np.int64)


def registered_orders() -> list[str]:
    """Orders the anchors can name at this commit: the registry's, and ``treelet`` when its module exists."""
    try:
        from coherence.ray_orders import RAY_ORDERS
    except ImportError:
        return []
    try:
        from coherence.treelet_orders import TreeletQueues
    except ImportError:
        return list(RAY_ORDERS)
    return list(dict.fromkeys([*RAY_ORDERS, TreeletQueues.name]))


def _per_ray(misses: dict, rays: int, levels: dict) -> dict:
    """Label -> level name -> misses per ray, from label -> misses per level (int64, (n_levels,))."""
    return {label: {name: float(m[k] / rays) for name, k in levels.items()} for label, m in misses.items()}


def _quotients(numerator, denominator, levels: dict, shift: float = 0.0, sign: float = 1.0) -> dict:
    """Level name -> ``shift + sign * numerator / denominator`` at that level (None where the denominator is 0)."""
    return {name: float(shift + sign * numerator[k] / denominator[k]) if denominator[k] else None
            for name, k in levels.items()}


def bounce_ratio(anchor: dict, work: Workload, levels: dict) -> dict:
    """Misses per extension ray at bounce >= ``anchor["bounce"]`` over misses per camera ray, as traced."""
    misses = misses_by_segment(work.trace, work.placed, work.hierarchy)
    ints = work.trace.segments.ints
    extension = ints[:, 3] != 2  # camera and bounce rays; shadow rays excluded
    groups = {"camera": extension & (ints[:, 2] == 0),
              f"bounce>={anchor['bounce']}": extension & (ints[:, 2] >= anchor["bounce"])}
    rays = {label: int(rows.sum()) for label, rows in groups.items()}
    per_ray = {label: misses[rows].sum(axis=0) / max(rays[label], 1) for label, rows in groups.items()}
    camera, later = per_ray.values()
    values = _quotients(later, camera, levels) if all(rays.values()) else {name: None for name in levels}
    return {"values": values, "rays": rays, "misses_per_ray": _per_ray(per_ray, 1, levels)}


def order_gain(anchor: dict, work: Workload, levels: dict) -> dict:
    """1 - misses(order) / misses(depth-first), and the same without the order's own records."""
    rows = np.arange(work.n_rays, dtype=np.int64)
    order = anchor["order"]
    misses = {"depth-first": work.order_misses("depth-first", rows), order: work.order_misses(order, rows),
              f"{order} without its own records": work.order_misses(order, rows, own_records=False)}
    base, with_own, bare = misses.values()
    return {"values": _quotients(with_own, base, levels, 1.0, -1.0),
            "gain_without_own_records": _quotients(bare, base, levels, 1.0, -1.0),
            "rays": {"all": work.n_rays}, "misses_per_ray": _per_ray(misses, work.n_rays, levels)}


def submission_change(anchor: dict, work: Workload, levels: dict, seed: int) -> dict:
    """misses(order, pixels in a seeded random order) / misses(order, row-major pixels) - 1."""
    shuffled = np.random.default_rng(seed).permutation(work.trace.n_pixels)
    order = anchor["order"]
    misses = {f"{order}, row-major": work.order_misses(order, np.arange(work.n_rays, dtype=np.int64)),
              f"{order}, random pixel order": work.order_misses(order, work.pixel_rows(shuffled))}
    row_major, random = misses.values()
    return {"values": _quotients(random, row_major, levels, -1.0), "rays": {"all": work.n_rays},
            "misses_per_ray": _per_ray(misses, work.n_rays, levels)}


def measure(anchor: dict, work: Workload, run: dict) -> dict:
    """One anchor's values per level and the misses per ray behind them."""
    levels = {name: work.level(name) for name in anchor["levels"]}
    if anchor["measure"] == "bounce_ratio":
        return bounce_ratio(anchor, work, levels)
    if anchor["order"] not in registered_orders():
        return {"values": {name: None for name in levels},
                "reason": f"order {anchor['order']!r} is not registered in coherence.ray_orders "
                          f"(registered: {', '.join(registered_orders()) or 'none'})"}
    result = order_gain(anchor, work, levels) if anchor["measure"] == "order_gain" \
        else submission_change(anchor, work, levels, run["submission_seed"])
    result["recipe"] = repr(work.recipe(anchor["order"]))
    return result


def run_anchors(work_dir: Path, size: int, only=None, data: Path = DATA) -> dict:
    """Measure the anchors (``only``: their ids) and write ``work_dir/anchors.json``."""
    run, anchors = load_anchors(data)
    chosen = [a for a in anchors if only is None or a["id"] in only]
    unknown = set(only or ()) - {a["id"] for a in anchors}
    if unknown:
        raise ValueError(f"--only: no anchor {', '.join(sorted(unknown))} in {data.name}")
    record = {"size": size, "commit": git_commit(), "machine": machine(),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "run": run, "anchors": {}}
    workloads = {}
    begun = time.perf_counter()
    for anchor in chosen:
        depth = int(anchor.get("max_depth", run["max_depth"]))
        started = time.perf_counter()
        if depth not in workloads:
            workloads[depth] = Workload.cached(run, size, depth)
        result = measure(anchor, workloads[depth], run)
        result["max_depth"] = depth
        result["seconds"] = round(time.perf_counter() - started, 1)
        result["command"] = ("python docs/results/anchors.py run --work OUT "
                             f"--size {size} --only {shlex.quote(anchor['id'])}")
        record["anchors"][anchor["id"]] = result
        print(f"{anchor['id']}: {result['values']} ({result['seconds']} s)", flush=True)
    record["seconds"] = round(time.perf_counter() - begun, 1)
    record["scene_bytes"] = {str(depth): work.placed.scene_bytes for depth, work in workloads.items()}
    work_dir.mkdir(parents=True, exist_ok=True)
    target = work_dir / "anchors.json"
    temporary = target.with_suffix(".json.tmp")
    temporary.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    temporary.replace(target)
    return record


def _number(value) -> str:
    return "—" if value is None else f"{value:.3g}"


def _stamp(record: dict) -> str:
    return (f"{STAMP_PREFIX} `python docs/results/anchors.py run --work OUT --size {record['size']}` at commit "
            f"`{record['commit']}` ({record['date']}, {record['seconds']:.0f} s on {record['machine']}).")


def _verdict_rows(anchors: list, record: dict) -> list:
    """One row per anchor: its published figure and rule, our values in ``record`` and the verdict."""
    rows = []
    for anchor in anchors:
        result = record["anchors"].get(anchor["id"])
        values = result["values"] if result else {}
        measured = ", ".join(f"{level} {_number(values.get(level))}" for level in anchor["levels"]) if result \
            else "not run"
        rows.append({"anchor": anchor["id"], "published": anchor["published"], "citation": anchor["citation"],
                     "order": anchor["order"], "quantity": anchor["measure"],
                     "rule": f"{anchor['rule']} {anchor['threshold']:g}", "ours": measured,
                     "verdict": verdict(values, anchor["rule"], anchor["threshold"]) if result else NOT_MEASURED,
                     "ours, order's records free": ", ".join(f"{level} {_number(value)}" for level, value in
                                                             result.get("gain_without_own_records", {}).items())
                     if result else ""})
    return rows


def page_text(records: list, data: Path = DATA) -> str:
    """The page ``anchors.md``: the data file's anchors, the measurements of ``records`` (one per image size,
    the first in full, the others in a table of their own), stamps."""
    import pandas as pd

    run, anchors = load_anchors(data)
    record = records[0]
    size = record["size"]
    stamp = _stamp(record)
    blocks = ["# Anchors: published findings on reordering incoherent rays",
              f"""Each published finding is stated as a claim our path-traced traces can test,
with the rule that decides it, in `docs/results/anchors.toml` (committed before
anything was measured). Ours: {run['scene']} at {size}×{size} pixels, {run['spp']} samples per
pixel, seed {run['seed']}, bounce limit {run['max_depth']} unless the anchor says otherwise;
one process owns every ray; the {run['hierarchy']} hierarchy on empty caches;
the {run['layout']} layout, whose records of the scene and its tree take
{max(record['scene_bytes'].values()):,} bytes. A "miss" at a level is an access that level could not
serve. Citations name where the figure was read; "body not checked" means only
the abstract was seen. A small image on a scene that fits in the L3 tests the
direction of each finding, not its size.""",
              "## Verdicts"]
    rows = _verdict_rows(anchors, record)
    blocks += [markdown_table(pd.DataFrame(rows)), stamp]
    blocks.append("""The last column is not part of any rule: an order's gain if its ray states and
queue entries cost no memory traffic (its pieces replayed alone).""")
    for other in records[1:]:
        blocks.append(f"## The same at {other['size']}×{other['size']} pixels")
        table = pd.DataFrame(_verdict_rows(anchors, other))
        blocks += [markdown_table(table[["anchor", "order", "rule", "ours", "verdict", "ours, order's records free"]]),
                   _stamp(other)]
    blocks.append(f"## Each anchor, at {size}×{size} pixels")
    for anchor in anchors:
        result = record["anchors"].get(anchor["id"])
        blocks.append(f"### `{anchor['id']}`")
        blocks.append(f"{anchor['reference']}.\n\n- Finding: {anchor['finding']}\n"
                      f"- Published: {anchor['published']} ({anchor['citation']}).\n"
                      f"- Our claim: {anchor['claim']}")
        if result is None:
            blocks.append("Not run in this record.")
            continue
        if "reason" in result:
            blocks.append(f"Not measured: {result['reason']}. Reproduce: `{result['command']}`.")
            continue
        table = pd.DataFrame([{"rays": key, **{level: value for level, value in per_level.items()}}
                              for key, per_level in result["misses_per_ray"].items()])
        recipe = f"; order `{result['recipe']}`" if "recipe" in result else ""
        blocks.append(f"Misses per ray (bounce limit {result['max_depth']}{recipe}; rays counted: "
                      + ", ".join(f"{key} {count}" for key, count in result["rays"].items()) + "):")
        blocks += [markdown_table(table), stamp]
        blocks.append(f"{anchor['measure']}: " + ", ".join(f"{level} {_number(value)}"
                                                           for level, value in result["values"].items())
                      + f" (rule {anchor['rule']} {anchor['threshold']:g}): "
                      f"**{verdict(result['values'], anchor['rule'], anchor['threshold'])}**. "
                      f"Reproduce: `{result['command']}`.")
        if "gain_without_own_records" in result:
            blocks.append("Not part of the rule: the gain if the order's ray states and queues cost nothing, "
                          + ", ".join(f"{level} {_number(value)}"
                                      for level, value in result["gain_without_own_records"].items()) + ".")
    return "\n\n".join(blocks) + "\n"


def write_page(records: list, pages: Path = HERE) -> Path:
    """Store ``records`` (one per image size) as ``anchors.json`` and write ``anchors.md`` beside this script."""
    (pages / "anchors.json").write_text(json.dumps(records, indent=1) + "\n", encoding="utf-8")
    path = pages / "anchors.md"
    path.write_text(page_text(records), encoding="utf-8")
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="step", required=True)
    run = sub.add_parser("run", help="measure the anchors into --work/anchors.json")
    run.add_argument("--work", type=Path, required=True)
    run.add_argument("--size", type=int, default=64, help="image width and height (default 64)")
    run.add_argument("--only", nargs="+", metavar="ID")
    page = sub.add_parser("page", help="write anchors.md from each --work's anchors.json (default: the stored "
                                       "records); the first in full, the others as tables of their own")
    page.add_argument("--work", type=Path, nargs="+")
    args = parser.parse_args(argv)
    if args.step == "run":
        run_anchors(args.work, args.size, args.only)
        return
    if args.work:
        records = [json.loads((work / "anchors.json").read_text(encoding="utf-8")) for work in args.work]
    else:
        records = json.loads((HERE / "anchors.json").read_text(encoding="utf-8"))
    print(write_page(records))


if __name__ == "__main__":
    main()
