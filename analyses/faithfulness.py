"""The faithfulness section: what the robustness study says of the verdict, as Markdown, from ``robustness.json`` alone.

>>> from analyses.faithfulness import faithfulness_markdown      # doctest: +SKIP
>>> text = faithfulness_markdown(json.load(open("robustness/robustness.json")))

:func:`faithfulness_markdown` is a pure function of the summary that
``coherence robustness`` writes (:func:`analyses.robustness_output.robustness_summary`):
every figure of the section is read from it or computed from it, none is
typed in. Per scene: the 5th, 50th and 95th percentiles of the one-process
B - S and DB - S time differences (in % of S's time), of the verdict's
margin and of every mapping's coherence and imbalance losses, the verdict's
probability, the three unknowns of largest Morris
``mu*`` with their indices and flip regions, the size check (the
one-process differences at half and twice the size) when the study ran it,
and the Sobol indices when it ran Sobol's design.
Overall: which mechanism
(:data:`MECHANISMS`) matters most, by the rule of :func:`mechanism_shares`.
It names the command, seed and commit the summary records, states the image
size against :data:`analyses.robustness_size.VERDICT_MIN_SIZE` and the scenes,
trajectories and Sobol design against the budgeted study
(:func:`analyses.robustness_output.study_budget`), and says which of the study's figures
the project holds (:class:`tracer.scenes.study.StudyScene`) and which it
does not.

Regenerate a page from a stored summary with
``python -m analyses.faithfulness robustness.json faithfulness.md``, or run
the study and write it at once with ``coherence robustness ...
--faithfulness-md FILE``.
"""
from __future__ import annotations

import dataclasses
import sys

from analyses.robustness_size import VERDICT_MIN_SIZE
from rtcommon.validate import InputError

__all__ = ["MECHANISMS", "mechanism_of", "mechanism_shares", "faithfulness_markdown",
           "write_faithfulness", "main"]

#: The mechanisms of the model the unknowns belong to, mechanism -> unknowns
#: (names of :data:`coherence.unknowns.UNKNOWNS`). An unknown in none of
#: them is a mechanism of its own, under its own name.
MECHANISMS = {
    "memory latencies": ("memory_latency", "bcache_latency"),
    "physical page placement": ("page_placement",),
    "memory image": ("memory_image",),
    "other users": ("background_load", "background_footprint"),
    "time slice": ("quantum_cycles",),
    "data TLB": ("data_tlb", "dtb_miss_cycles"),
    "operation costs": ("square_root_cycles", "cost_node_visit", "cost_test_sphere", "cost_test_triangle",
                        "cost_light_read", "cost_ray"),
    "tree memory": ("tree_variant",),
}

#: The summary's keys the section reads.
_REQUIRED = ("parameters", "command", "commit", "scenes")
_PARAMETERS_REQUIRED = ("size", "seed", "trajectories", "sobol", "verdict_n_processes", "scenes")
_SCENE_REQUIRED = ("n_evaluations", "b_minus_s", "db_minus_s", "margin", "p_load_balance", "mu_star", "top", "flip")


def mechanism_of(factor: str) -> str:
    """The mechanism of :data:`MECHANISMS` unknown ``factor`` belongs to (its own name if none)."""
    for mechanism, factors in MECHANISMS.items():
        if factor in factors:
            return mechanism
    return factor


def mechanism_shares(scenes: dict) -> dict:
    """Per mechanism, its share of the largest Morris ``mu*`` in each scene and their mean.

    A scene's share of an unknown is its ``mu*`` over the scene's largest
    ``mu*`` (0 when every ``mu*`` is 0); a mechanism's share is the largest
    share of its unknowns; the mechanism that matters most overall has the
    largest mean share over the scenes, every scene weighing the same.

    Parameters
    ----------
    scenes : dict
        Scene -> its summary (``mu_star``: unknown -> float).

    Returns
    -------
    dict
        Mechanism -> ``{"scenes": {scene: share}, "mean": float}``, the
        largest mean first (ties in the order of first appearance).
    """
    shares = {}
    for scene, summary in scenes.items():
        mu_star = summary["mu_star"]
        largest = max(mu_star.values(), default=0.0)
        for factor, value in mu_star.items():
            share = value / largest if largest > 0 else 0.0
            entry = shares.setdefault(mechanism_of(factor), {}).setdefault(scene, 0.0)
            shares[mechanism_of(factor)][scene] = max(entry, share)
    out = {mechanism: {"scenes": {scene: per.get(scene, 0.0) for scene in scenes},
                       "mean": sum(per.get(scene, 0.0) for scene in scenes) / len(scenes)}
           for mechanism, per in shares.items()}
    return dict(sorted(out.items(), key=lambda item: -item[1]["mean"]))


def _number(value) -> str:
    return "n/a" if value is None else f"{value:.4g}"


def _percent(value) -> str:
    return "n/a" if value is None else f"{100.0 * value:.4g}"


def _flip_text(rule, unit: str) -> str:
    if isinstance(rule, str):
        return rule
    agrees = f"agrees with {_percent(rule['agreement'])}% of samples"
    if "threshold" in rule:
        return f"load balance when {rule['load_balance_when']} {_number(rule['threshold'])} {unit}".rstrip() + \
            f" ({agrees})"
    chosen = ", ".join(rule["load_balance_choices"]) or "no choice"
    return f"load balance with {chosen} ({agrees})"


def _check(summary) -> None:
    if not isinstance(summary, dict):
        raise InputError(f"faithfulness: the robustness summary must be a JSON object, got {type(summary).__name__}")
    missing = [key for key in _REQUIRED if key not in summary]
    if missing:
        raise InputError(f"faithfulness: the robustness summary has no {', '.join(missing)}; "
                         f"write it with this version of coherence robustness")
    missing = [key for key in _PARAMETERS_REQUIRED if key not in summary.get("parameters", {})]
    if missing:
        raise InputError(f"faithfulness: the robustness summary's parameters have no {', '.join(missing)}; "
                         f"write it with this version of coherence robustness")
    if not summary["scenes"]:
        raise InputError("faithfulness: the robustness summary has no scenes")
    for scene, scene_summary in summary["scenes"].items():
        missing = [key for key in _SCENE_REQUIRED if key not in scene_summary]
        if missing:
            raise InputError(f"faithfulness: scene {scene!r} of the robustness summary has no {', '.join(missing)}")


def _run_paragraph(summary: dict) -> list[str]:
    """What the study ran against the budgeted study (:func:`analyses.robustness_output.study_budget`)."""
    from analyses.robustness_output import study_budget

    p = summary["parameters"]
    budget = study_budget(p)
    ran = (f"This study ran {p['trajectories']} Morris trajectories on {', '.join(p['scenes'])}, "
           + (f"then Sobol with N = {p['sobol']}" if p["sobol"] else "and no Sobol design") + ".")
    asked = (f"The study the verdict is budgeted for runs {budget['trajectories']} Morris trajectories "
             f"({budget['morris_evaluations']} evaluations) on each of {', '.join(budget['scenes'])}, then Sobol "
             f"with N = {budget['sobol_base_samples']} over the top unknowns, at {VERDICT_MIN_SIZE} x "
             f"{VERDICT_MIN_SIZE} pixels or more.")
    if budget["met"]:
        return [f"{ran} {asked} This study is that study or larger.", ""]
    short = [f"not run on {', '.join(budget['scenes_not_run'])}"] if budget["scenes_not_run"] else []
    if p["trajectories"] < budget["trajectories"]:
        short.append(f"{p['trajectories']} trajectories instead of {budget['trajectories']}")
    if p["sobol"] < budget["sobol_base_samples"]:
        short.append("no Sobol indices" if not p["sobol"] else f"Sobol with N = {p['sobol']}")
    if p["size"] < VERDICT_MIN_SIZE:
        short.append(f"{p['size']} x {p['size']} pixels")
    return [f"{ran} {asked} So this page is short of it: {'; '.join(short)}. Its ranges and rankings hold for "
            "the scenes and design it names, not for the whole study.", ""]


def _size_check_lines(check: dict) -> list[str]:
    """The size check of one scene (:mod:`analyses.robustness_size`) as a table."""
    small, reference = check["small_size"], check["reference_size"]
    lines = [f"Size check: the one-process differences (%) of {len(check['samples'])} samples at {small} x {small} "
             f"against {reference} x {reference}; a quantity passes when every point is within "
             f"{_percent(check['tolerance'])}% of the larger image's value.",
             "",
             f"| quantity | sample | at {small} | at {reference} | relative difference | quantity passed |",
             "|---|---:|---:|---:|---:|---|"]
    for name, entry in check["quantities"].items():
        for sample, low, high, relative in zip(check["samples"], entry["small"], entry["reference"],
                                               entry["relative_difference"]):
            lines.append(f"| {name} | {sample} | {_percent(low)} | {_percent(high)} | {_number(relative)} | "
                         f"{'yes' if entry['passed'] else 'no'} |")
    return lines + [""]


def _sobol_lines(sobol: dict, held_at) -> list[str]:
    """One scene's Sobol indices of the verdict's margin as a table, in the order the study chose the unknowns."""
    held = "" if held_at is None else f" at unit coordinate {_number(held_at)} of their ranges"
    lines = [f"Sobol indices of the verdict's margin over the {len(sobol['factors'])} unknowns of largest mu* "
             f"(Saltelli's design, N = {sobol['base_samples']}, {sobol['n_evaluations']} evaluations; every other "
             f"unknown held{held}). These are estimates: the first-order one can come out below 0 for an unknown "
             "whose first-order effect is nil.",
             "",
             "| unknown | mechanism | first order S1 | total ST |",
             "|---|---|---:|---:|"]
    for factor in sobol["factors"]:
        lines.append(f"| {factor} | {mechanism_of(factor)} | {_number(sobol['S1'][factor])} | "
                     f"{_number(sobol['ST'][factor])} |")
    return lines + [""]


def _study_paragraph(n_processes: int) -> list[str]:
    from tracer.scenes.study import StudyScene

    fields = [f"`{field.name}`" for field in dataclasses.fields(StudyScene) if field.name not in ("name", "geometry")]
    return [
        "## Against the study's own figures",
        "",
        "Of the study's figures the project holds only its scene table (`tracer/scenes/study.py`, one row per "
        f"scene: {', '.join(fields)}). The scene loader takes element counts and ray depths from it and the "
        "paper's fit takes the sequential Strip times as targets. None of them is a difference between pixel "
        f"orders, a loss at {n_processes} processes or a verdict, so none is set against the ranges above.",
        "",
        "Not in the project: the study's one-process time of each mapping (so its B - S and DB - S differences), "
        f"its times and speed-ups at {n_processes} processes, and so its own verdict per scene. This page makes no "
        "comparison with them.",
        "",
    ]


def faithfulness_markdown(summary: dict) -> str:
    """The faithfulness section of ``summary`` (the parsed ``robustness.json``) as Markdown.

    Raises
    ------
    rtcommon.validate.InputError
        If the summary lacks a key the section reads (one written by an
        older ``coherence robustness``, say).
    """
    from analyses.robustness_output import study_budget

    _check(summary)
    p = summary["parameters"]
    scenes = summary["scenes"]
    units = {factor["name"]: factor.get("unit", "") for factor in p.get("factors", [])}
    size = p["size"]
    title = "# Faithfulness: the verdict across what the model does not know"
    if p["sobol"]:
        title += f", with Sobol indices on {', '.join(scenes)}"
    lines = [
        title,
        "",
        "Generated by `python -m analyses.faithfulness ROBUSTNESS_JSON PAGE` from the `robustness.json` that the "
        "command below wrote (in the docs it is stored beside this page, under the page's name with `.json`); do "
        "not edit by hand.",
        "",
        f"- Command: `{summary['command']}`",
        f"- Seed: {p['seed']}",
        f"- Commit: `{summary['commit']}`",
        f"- Image: {size} x {size} pixels; {p['trajectories']} Morris trajectories over "
        f"{len(p.get('factors', []))} unknowns; the verdict at {p['verdict_n_processes']} processes.",
        "",
    ]
    lines += _run_paragraph(summary)
    if size < VERDICT_MIN_SIZE:  # a smaller study is a first look
        lines += [f"This is a first look: the {p['verdict_n_processes']}-process losses and the verdict are meant "
                  f"at {VERDICT_MIN_SIZE} x {VERDICT_MIN_SIZE} pixels or more, and this study ran at {size} x {size}. "
                  "On a small image the mappings have few tasks per process, so their imbalance losses, and with "
                  "them the verdict's margin, are overstated (see each scene's losses).", ""]
    shares = mechanism_shares(scenes)
    most = next(iter(shares))
    lines += [
        "## Which mechanism matters most",
        "",
        f"Overall: **{most}** (mean share {_number(shares[most]['mean'])}). A scene's share of an unknown is its "
        "Morris mu* of the verdict's margin over the scene's largest mu*; a mechanism's share is the largest "
        "of its unknowns'; the mean weighs every scene the same.",
        "",
        "| mechanism | " + " | ".join(scenes) + " | mean |",
        "|---|" + "---:|" * (len(scenes) + 1),
    ]
    for mechanism, entry in shares.items():
        lines.append(f"| {mechanism} | " + " | ".join(_number(entry["scenes"][scene]) for scene in scenes) +
                     f" | {_number(entry['mean'])} |")
    lines.append("")
    lines += ["## Per scene", "",
              "Differences are one-process user times relative to S's, in % of S's time "
              "((T_B - T_S) / T_S); the margin is the largest imbalance loss of any mapping minus the largest "
              "coherence or dispatch loss, positive when the verdict is \"load balance\".", ""]
    for scene, s in scenes.items():
        lines += [
            f"### {scene}",
            "",
            f"P(load balance) = {_number(s['p_load_balance'])} over {s['n_evaluations']} evaluations "
            f"(budgeted: {study_budget(p)['morris_evaluations']}).",
            "",
            "| quantity | 5th | 50th | 95th |",
            "|---|---:|---:|---:|",
            "| one-process B - S (%) | " + " | ".join(_percent(s["b_minus_s"][f"p{q}"]) for q in (5, 50, 95)) + " |",
            "| one-process DB - S (%) | " + " | ".join(_percent(s["db_minus_s"][f"p{q}"]) for q in (5, 50, 95)) +
            " |",
            "| verdict's margin | " + " | ".join(_number(s["margin"][f"p{q}"]) for q in (5, 50, 95)) + " |",
            "",
        ]
        if s.get("losses"):
            lines += [f"Losses at {p['verdict_n_processes']} processes (fractions), 5th, 50th and 95th percentiles:",
                      "",
                      "| mapping | coherence 5th | coherence 50th | coherence 95th | imbalance 5th | imbalance 50th | "
                      "imbalance 95th |",
                      "|---|---:|---:|---:|---:|---:|---:|"]
            for mapping, kinds in s["losses"].items():
                cells = [_number(kinds.get(kind, {}).get(f"p{q}")) for kind in ("coherence", "imbalance")
                         for q in (5, 50, 95)]
                lines.append(f"| {mapping} | " + " | ".join(cells) + " |")
            lines.append("")
        if s.get("size_check"):
            lines += _size_check_lines(s["size_check"])
        lines += ["| rank | unknown | mechanism | mu* | flip region |",
                  "|---:|---|---|---:|---|"]
        for rank, factor in enumerate(s["top"], start=1):
            lines.append(f"| {rank} | {factor} | {mechanism_of(factor)} | {_number(s['mu_star'][factor])} | "
                         f"{_flip_text(s['flip'][factor], units.get(factor, ''))} |")
        lines.append("")
        if s.get("sobol"):
            lines += _sobol_lines(s["sobol"], p.get("sobol_held_at"))
    lines += _study_paragraph(p["verdict_n_processes"])
    return "\n".join(lines)


def write_faithfulness(summary: dict, path) -> None:
    """Write :func:`faithfulness_markdown` of ``summary`` to ``path`` (a temporary name, then renamed),
    creating its folder if needed."""
    from pathlib import Path

    from rtcommon.files import write_text_atomic

    text = faithfulness_markdown(summary)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text)


def _read_summary(path) -> dict:
    import json

    from rtcommon.files import read_text_file, regular_file

    text = read_text_file(regular_file(path, "a robustness.json file"), "a robustness.json file")
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise InputError(f"{path}:{error.lineno}: not JSON ({error.msg}); expected the robustness.json "
                         f"that coherence robustness writes") from None


def main(argv=None) -> int:
    """``python -m analyses.faithfulness ROBUSTNESS_JSON [MARKDOWN]``: write (or print) the section."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m analyses.faithfulness",
                                     description="the faithfulness section (Markdown) from robustness.json")
    parser.add_argument("summary", metavar="ROBUSTNESS_JSON", help="robustness.json of coherence robustness")
    parser.add_argument("out", metavar="MARKDOWN", nargs="?", help="file to write (default: print it)")
    args = parser.parse_args(argv)
    try:
        summary = _read_summary(args.summary)
        if args.out:
            write_faithfulness(summary, args.out)
        else:
            sys.stdout.write(faithfulness_markdown(summary))
    except (InputError, OSError) as error:
        print(f"{parser.prog}: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
