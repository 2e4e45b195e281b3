"""The bytes the robustness study's shared line addresses hold, per scene, against its budget.

For every scene of ``--scenes`` at ``--size``, every tree variant and every memory image the study samples
(:data:`analyses.robustness_factors.FACTORS`), with the study-era hierarchy and its data TLB and a seeded
random page placement: :func:`coherence.pixel_lines.pixel_lines` with the hierarchy, which takes the certain
first-level hits out. Printed per trace: every line access, the accesses kept and the page runs, the bytes
held at the peak (:func:`coherence.pixel_lines.held_bytes`) beside
:data:`analyses.robustness.LINES_BUDGET`, the CPU time (user and system) of the call and the growth of this
process's peak resident set during it (measured where Linux lets the peak be reset, ``/proc/self/clear_refs``).
With ``--peer``, beside it the same lines made with every access held and then taken out
(:func:`coherence.pixel_lines.take_out_certain_hits`): equal arrays, and its CPU time and peak. Traces are
rendered or loaded from the trace cache, and the kernels compiled on a small scene, untimed. Ends with one
JSON line.

    python benchmarks/bench_pixel_lines.py [--size 256] [--scenes balls tetra ...] [--images alpha1997 ...]
                                           [--variants all|base] [--peer]
"""
import argparse
import json
import resource
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from analyses.robustness import LINES_BUDGET, ROBUSTNESS_EXPERIMENT  # noqa: E402
from analyses.robustness_factors import FACTORS, factor_values, sample_setup  # noqa: E402
from tracer.scenes.catalog import PAPER_SCENES  # noqa: E402

CHOICES = {entry.name: entry.choices for entry in FACTORS}


def peak_rss() -> int:
    """This process's peak resident set, bytes."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM"):
            return int(line.split()[1]) * 1024
    return 0


def reset_peak() -> bool:
    """Reset the peak resident set to the current one; False where the system does not let it."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def measured(function):
    """``function()``, its user and system CPU seconds and the growth of the peak resident set (None when it
    could not be reset)."""
    resettable = reset_peak()
    before_peak = peak_rss()
    start = resource.getrusage(resource.RUSAGE_SELF)
    result = function()
    end = resource.getrusage(resource.RUSAGE_SELF)
    growth = peak_rss() - before_peak if resettable else None
    return result, end.ru_utime - start.ru_utime, end.ru_stime - start.ru_stime, growth


def sample(scene: str, size: int, variant: str, image: str):
    """(trace, placed, hierarchy) of one sample: the robustness base at ``size`` with ``variant`` and ``image``,
    the data TLB on, a random page placement of seed 0, every other unknown at the middle of its range."""
    from analyses.traces import cached_trace
    from coherence.studies import place_layout

    values = {**factor_values(np.full(len(FACTORS), 0.5)), "memory_image": image, "tree_variant": variant,
              "data_tlb": "on", "page_placement": "random"}
    setup = sample_setup(replace(ROBUSTNESS_EXPERIMENT, scene=scene, size=size), values, 0)
    experiment = setup.experiment
    scene_object, trace, _ = cached_trace(experiment.scene, experiment.size, cache_dir=experiment.cache_dir,
                                          kd=experiment.kd_builder(), max_depth=experiment.max_depth, progress=False,
                                          workload=experiment.workload, tree_variant=variant)
    hierarchy = experiment.hierarchy_object()
    placed = place_layout(experiment.layout_object(), trace, scene_object).with_pages(setup.machine.page_placement,
                                                                                      hierarchy)
    return trace, placed, hierarchy


def one(scene: str, size: int, variant: str, image: str, peer: bool) -> dict:
    from coherence.pixel_lines import held_bytes, pixel_lines, take_out_certain_hits

    trace, placed, hierarchy = sample(scene, size, variant, image)
    np.asarray(trace.records).sum()  # the trace's pages in memory before the clock starts
    line_size = hierarchy.levels[0].line_size
    lines, user, system, growth = measured(lambda: pixel_lines(trace, placed, line_size, hierarchy=hierarchy))
    offsets = line_offsets(trace, placed, line_size)
    longest = int(np.max(np.diff(offsets))) if offsets.size > 1 else 0
    held = held_bytes(lines.addresses.size, lines.pixel_writes.size, lines.page_runs.size, longest)
    row = {"scene": scene, "variant": variant, "image": image, "accesses": int(offsets[-1]),
           "kept": int(lines.addresses.size), "runs": int(lines.page_runs.size), "held_bytes": held,
           "fits": held <= LINES_BUDGET, "user_s": user, "sys_s": system, "rss_growth_bytes": growth}
    del lines
    if peer:
        def held_then_taken():
            return take_out_certain_hits(pixel_lines(trace, placed, line_size), hierarchy)

        again = pixel_lines(trace, placed, line_size, hierarchy=hierarchy)
        taken, user, system, growth = measured(held_then_taken)
        row["peer_equal"] = all(np.array_equal(a, b) for a, b in zip(again, taken))
        row.update(peer_user_s=user, peer_sys_s=system, peer_rss_growth_bytes=growth)
    return row


def line_offsets(trace, placed, line_size: int) -> np.ndarray:
    """Offsets of every pixel's line accesses of ``trace``, none taken out (int64, shape (P + 1,))."""
    from coherence.pixel_lines import _pixel_line_offsets

    pixel_offsets = np.asarray(trace.pixel_offsets, dtype=np.int64)
    offsets = np.zeros(pixel_offsets.shape[0], dtype=np.int64)
    _pixel_line_offsets(np.asarray(trace.records), pixel_offsets, placed.placement, line_size.bit_length() - 1,
                        offsets)
    return offsets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--scenes", nargs="+", default=list(PAPER_SCENES))
    parser.add_argument("--images", nargs="+", default=list(CHOICES["memory_image"]))
    parser.add_argument("--variants", choices=["all", "base"], default="all")
    parser.add_argument("--peer", action="store_true")
    args = parser.parse_args()
    variants = list(CHOICES["tree_variant"]) if args.variants == "all" else [ROBUSTNESS_EXPERIMENT.tree_variant]
    one("tetra", 16, variants[0], args.images[0], args.peer)  # compiles the kernels, untimed
    gib = float(1 << 30)
    print(f"budget LINES_BUDGET = {LINES_BUDGET / gib:.2f} GiB; size {args.size}; page placement random, "
          f"data TLB on", flush=True)
    rows = []
    for scene in args.scenes:
        for variant in variants:
            for image in args.images:
                row = one(scene, args.size, variant, image, args.peer)
                rows.append(row)
                growth = row["rss_growth_bytes"]
                peak = f"{growth / gib:5.2f}" if growth is not None else "?"
                text = (f"{scene:6s} {variant:36s} {image:10s} accesses {row['accesses'] / 1e6:7.1f} M, kept "
                        f"{row['kept'] / 1e6:7.1f} M, runs {row['runs'] / 1e6:6.1f} M: held {row['held_bytes'] / gib:5.2f} "
                        f"GiB ({'fits' if row['fits'] else 'OVER'}; 9 B an access would say "
                        f"{9 * row['accesses'] / gib:5.2f}), CPU {row['user_s']:5.2f} + {row['sys_s']:4.2f} s, "
                        f"peak RSS +{peak} GiB")
                if args.peer:
                    peer_growth = row["peer_rss_growth_bytes"]
                    peer_peak = f"{peer_growth / gib:5.2f}" if peer_growth is not None else "?"
                    text += (f"; every access held, then taken out: CPU {row['peer_user_s']:5.2f} + "
                             f"{row['peer_sys_s']:4.2f} s, peak RSS +{peer_peak} GiB, "
                             f"{'equal' if row['peer_equal'] else 'DIFFERENT'}")
                print(text, flush=True)
    worst = {scene: max(row["held_bytes"] for row in rows if row["scene"] == scene) for scene in args.scenes}
    for scene, held in worst.items():
        print(f"{scene}: at most {held / gib:.2f} GiB of {LINES_BUDGET / gib:.2f} "
              f"({'every trace fits' if held <= LINES_BUDGET else 'SOME TRACE DOES NOT FIT'})")
    print(json.dumps({"size": args.size, "budget_bytes": LINES_BUDGET, "rows": rows}))


if __name__ == "__main__":
    main()
