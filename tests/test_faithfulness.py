"""The faithfulness section: generated from a small real robustness study, every figure read back from the
Markdown and compared with the summary it came from; the mechanism rule on a hand-made case; bad input."""
from __future__ import annotations

import json
import re
import warnings
from dataclasses import replace

import pytest

from analyses.faithfulness import MECHANISMS, faithfulness_markdown, main, mechanism_shares
from analyses.robustness_size import VERDICT_MIN_SIZE
from analyses.robustness import ROBUSTNESS_EXPERIMENT, robustness
from analyses.robustness_factors import FACTORS
from analyses.robustness_output import robustness_summary, study_budget


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    base = replace(ROBUSTNESS_EXPERIMENT, size=16, cache_dir=str(tmp_path_factory.mktemp("cache")))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # DB has fewer blocks than processes at 16x16
        result = robustness(base, scenes=["tetra"], trajectories=2, seed=5)
    return json.loads(json.dumps(robustness_summary(result)))  # as read back from robustness.json


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _table(lines: list[str], header_start: str) -> list[list[str]]:
    """The body rows of the first table whose header row starts with ``header_start``."""
    start = next(i for i, line in enumerate(lines) if line.startswith(header_start))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append(_cells(line))
    return rows


def _close(text: str, value: float, scale: float = 1.0) -> bool:
    """Printed ``text`` (4 significant digits) equals ``value * scale``."""
    return float(text) == pytest.approx(value * scale, rel=1e-3, abs=1e-12)


def test_every_figure_of_the_section_is_the_summarys(summary):
    """Parse the Markdown of a real 16x16 tetra study (2 trajectories) and check each figure against the JSON:
    command, seed, commit, size, trajectories, per scene P(load balance), evaluations, the 5/50/95th
    percentiles of B - S, DB - S (in %), the margin and every mapping's losses, the top three unknowns with mu* and flip regions,
    and every mechanism's share recomputed here from mu*. Fails if faithfulness_markdown swaps two
    percentiles (for example ``(50, 5, 95)`` in the DB - S row)."""
    text = faithfulness_markdown(summary)
    lines = text.splitlines()
    p = summary["parameters"]
    assert re.search(r"^- Command: `(.*)`$", text, re.M).group(1) == summary["command"]
    assert summary["command"].startswith("coherence robustness --scenes tetra --size 16 --trajectories 2 --seed 5")
    assert int(re.search(r"^- Seed: (\d+)$", text, re.M).group(1)) == p["seed"] == 5
    assert re.search(r"^- Commit: `(.*)`$", text, re.M).group(1) == summary["commit"]
    image = re.search(r"^- Image: (\d+) x (\d+) pixels; (\d+) Morris trajectories over (\d+) unknowns", text, re.M)
    assert [int(g) for g in image.groups()] == [16, 16, 2, len(FACTORS)]
    assert f"meant at {VERDICT_MIN_SIZE} x {VERDICT_MIN_SIZE} pixels or more" in text  # 16 < VERDICT_MIN_SIZE

    for scene, s in summary["scenes"].items():
        section = lines[lines.index(f"### {scene}"):]
        found = re.search(r"P\(load balance\) = (\S+) over (\d+) evaluations", "\n".join(section[:4]))
        assert _close(found.group(1), s["p_load_balance"]) and int(found.group(2)) == s["n_evaluations"]
        rows = {row[0]: row[1:] for row in _table(section, "| quantity |")}
        # the mutation must be able to bite: the percentiles differ
        assert s["db_minus_s"]["p5"] < s["db_minus_s"]["p50"] < s["db_minus_s"]["p95"]
        for label, key, scale in (("one-process B - S (%)", "b_minus_s", 100.0),
                                  ("one-process DB - S (%)", "db_minus_s", 100.0),
                                  ("verdict's margin", "margin", 1.0)):
            for cell, q in zip(rows[label], (5, 50, 95)):
                assert _close(cell, s[key][f"p{q}"], scale), (label, q, cell)
        losses = {row[0]: row[1:] for row in _table(section, "| mapping |")}
        assert list(losses) == list(s["losses"])
        for mapping, cells in losses.items():
            expected = [s["losses"][mapping][kind][f"p{q}"] for kind in ("coherence", "imbalance") for q in (5, 50, 95)]
            assert all(_close(cell, value) for cell, value in zip(cells, expected)), (mapping, cells, expected)
        top = _table(section, "| rank |")
        assert [row[1] for row in top] == s["top"] and [int(row[0]) for row in top] == [1, 2, 3]
        for rank, factor, mechanism, mu_star, flip in top:
            assert _close(mu_star, s["mu_star"][factor])
            assert factor in MECHANISMS[mechanism]
            rule = s["flip"][factor]
            if isinstance(rule, str):
                assert flip == rule
            else:
                assert _close(re.search(r"agrees with (\S+)%", flip).group(1), rule["agreement"], 100.0)
                if "threshold" in rule:
                    when = re.search(rf"when {rule['load_balance_when']} (\S+)", flip)
                    assert _close(when.group(1), rule["threshold"])

    scenes = list(summary["scenes"])
    shares = {row[0]: row[1:] for row in _table(lines, "| mechanism |")}
    for mechanism, factors in MECHANISMS.items():
        per_scene = []
        for scene in scenes:
            mu = summary["scenes"][scene]["mu_star"]
            per_scene.append(max(mu[f] for f in factors) / max(mu.values()))
        assert [float(c) for c in shares[mechanism]] == pytest.approx(per_scene + [sum(per_scene) / len(scenes)],
                                                                       rel=1e-3, abs=1e-12), mechanism
    best = max(MECHANISMS, key=lambda m: float(shares[m][-1]))
    assert re.search(r"Overall: \*\*(.+?)\*\*", text).group(1) == best


def test_the_sobol_table_is_the_summarys_indices(tmp_path_factory):
    """A real 16x16 tetra study with Sobol's design (N = 2): the scene's Sobol table lists the unknowns Sobol
    varied, in the study's order, each with its mechanism, S1 and ST read back equal to the JSON's, and the
    design's N and evaluations; the Morris-only study's page has no such table. Fails if _sobol_lines swaps
    S1 and ST (they differ here) or the call to it is dropped."""
    base = replace(ROBUSTNESS_EXPERIMENT, size=16, cache_dir=str(tmp_path_factory.mktemp("cache")))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # DB has fewer blocks than processes at 16x16
        result = robustness(base, scenes=["tetra"], trajectories=2, seed=5, sobol=2, size_check=False)
    summary = json.loads(json.dumps(robustness_summary(result)))
    sobol = summary["scenes"]["tetra"]["sobol"]
    lines = faithfulness_markdown(summary).splitlines()
    assert any(sobol["S1"][f] != pytest.approx(sobol["ST"][f]) for f in sobol["factors"])
    rows = _table(lines, "| unknown | mechanism | first order S1 |")
    assert [row[0] for row in rows] == sobol["factors"]
    for factor, mechanism, first, total in rows:
        assert factor in MECHANISMS[mechanism] and _close(first, sobol["S1"][factor]) \
            and _close(total, sobol["ST"][factor])
    intro = next(line for line in lines if line.startswith("Sobol indices of the verdict's margin"))
    assert f"N = {sobol['base_samples']}, {sobol['n_evaluations']} evaluations" in intro
    without = dict(summary, scenes={"tetra": {k: v for k, v in summary["scenes"]["tetra"].items() if k != "sobol"}})
    assert not any(line.startswith("| unknown | mechanism |") for line in faithfulness_markdown(without).splitlines())


def test_the_page_states_the_run_against_the_budgeted_study(summary):
    """robustness.json records the budget (10 trajectories, 17 samples each over the 16 unknowns, Sobol N = 64,
    all five study scenes) and each scene's budgeted evaluations; the page of the 2-trajectory tetra study
    without Sobol names the four scenes not run, the trajectories, the missing Sobol design and the image below the verdict's
    size, and a summary of the full design at 256 x 256 says it is that study, at half that size not. Fails
    if study_budget leaves out the scenes not run (``not_run = []``) or the size
    (``parameters["size"] >= VERDICT_MIN_SIZE and`` dropped)."""
    budget = summary["budget"]
    assert budget["scenes"] == ["balls", "tetra", "shell", "room", "fluid"]
    assert budget["scenes_not_run"] == ["balls", "shell", "room", "fluid"] and budget["met"] is False
    assert budget["morris_evaluations"] == 10 * (len(FACTORS) + 1)
    assert summary["scenes"]["tetra"]["n_evaluations_budgeted"] == budget["morris_evaluations"]
    text = faithfulness_markdown(summary)
    short = re.search(r"So this page is short of it: (.*?)\. ", text).group(1)
    assert short == "not run on balls, shell, room, fluid; 2 trajectories instead of 10; no Sobol indices; 16 x 16 pixels"
    found = re.search(r"over (\d+) evaluations \(budgeted: (\d+)\)", text)
    assert [int(g) for g in found.groups()] == [summary["scenes"]["tetra"]["n_evaluations"], 10 * (len(FACTORS) + 1)]

    scenes = ["balls", "tetra", "shell", "room", "fluid"]
    full = {**summary, "parameters": {**summary["parameters"], "scenes": scenes, "trajectories": 10, "sobol": 64,
                                      "size": VERDICT_MIN_SIZE},
            "scenes": {scene: summary["scenes"]["tetra"] for scene in scenes}}
    text = faithfulness_markdown(full)
    assert "This study is that study or larger." in text and "short of it" not in text
    small = {**full, "parameters": {**full["parameters"], "size": VERDICT_MIN_SIZE // 2}}
    assert study_budget(small["parameters"])["met"] is False
    assert re.search(r"short of it: (.*?)\. ", faithfulness_markdown(small)).group(1) == (
        f"{VERDICT_MIN_SIZE // 2} x {VERDICT_MIN_SIZE // 2} pixels")
    one_short = {**full, "parameters": {**full["parameters"], "scenes": scenes[1:]},
                 "scenes": {scene: summary["scenes"]["tetra"] for scene in scenes[1:]}}
    assert re.search(r"short of it: (.*?)\. ", faithfulness_markdown(one_short)).group(1) == "not run on balls"


def test_the_size_check_table_is_the_summarys(summary):
    """Each row of a scene's size-check table gives the quantity, its sample and both sizes' values (in %) and
    relative difference as robustness.json holds them, with the smaller size's column first. Fails if
    _size_check_lines zips the reference values before the small ones."""
    check = summary["scenes"]["tetra"]["size_check"]
    lines = faithfulness_markdown(summary).splitlines()
    section = lines[lines.index("### tetra"):]
    header = next(line for line in section if line.startswith("| quantity | sample |"))
    assert _cells(header)[2:4] == [f"at {check['small_size']}", f"at {check['reference_size']}"]
    rows = _table(section, "| quantity | sample |")
    expected = [(name, sample, small, reference, relative, entry["passed"])
                for name, entry in check["quantities"].items()
                for sample, small, reference, relative in zip(check["samples"], entry["small"], entry["reference"],
                                                              entry["relative_difference"])]
    assert len(rows) == len(expected) == 2 * len(check["samples"])
    # the mutation must be able to bite: the two sizes differ at some point
    assert any(small != reference for _, _, small, reference, _, _ in expected)
    for row, (name, sample, small, reference, relative, passed) in zip(rows, expected):
        assert row[0] == name and int(row[1]) == sample
        for cell, value, scale in ((row[2], small, 100.0), (row[3], reference, 100.0), (row[4], relative, 1.0)):
            assert cell == "n/a" if value is None else _close(cell, value, scale), (name, sample, cell, value)
        assert row[5] == ("yes" if passed else "no")


def test_mechanism_shares_by_hand():
    """Two scenes, mu* set by hand: in scene a the node-visit cost has the largest mu* (4), the memory
    latency 2 and the B-cache latency 3, so memory latencies take 3/4; in scene b memory latency leads (1)
    and costs are 0.5. Means: memory latencies (0.75 + 1) / 2, operation costs (1 + 0.5) / 2. Fails if a
    mechanism's share sums its unknowns' shares instead of taking the largest."""
    zeros = {entry.name: 0.0 for entry in FACTORS}
    scenes = {"a": {"mu_star": {**zeros, "cost_node_visit": 4.0, "memory_latency": 2.0, "bcache_latency": 3.0}},
              "b": {"mu_star": {**zeros, "memory_latency": 1.0, "cost_ray": 0.5, "cost_test_sphere": 0.25}}}
    shares = mechanism_shares(scenes)
    assert list(shares)[0] == "memory latencies"
    assert shares["memory latencies"] == {"scenes": {"a": 0.75, "b": 1.0}, "mean": 0.875}
    assert shares["operation costs"] == {"scenes": {"a": 1.0, "b": 0.5}, "mean": 0.75}
    assert shares["tree memory"]["mean"] == 0.0
    # every unknown of the study belongs to exactly one named mechanism
    assert sorted(f for factors in MECHANISMS.values() for f in factors) == sorted(e.name for e in FACTORS)


def test_regenerates_from_a_stored_summary_and_refuses_bad_input(summary, tmp_path, capsys):
    """``python -m analyses.faithfulness`` writes the same Markdown from robustness.json as the function gives,
    creating the folder; a missing file, a file that is not JSON and a summary without its command each give
    a one-line error and exit 2, writing nothing, as does one whose parameters lack ``sobol``. Fails if main
    drops the check of the summary's keys (or of its parameters': a KeyError traceback)."""
    stored = tmp_path / "robustness.json"
    stored.write_text(json.dumps(summary, indent=2), encoding="utf-8")
    out = tmp_path / "docs" / "results" / "faithfulness.md"
    assert main([str(stored), str(out)]) == 0
    assert out.read_text(encoding="utf-8") == faithfulness_markdown(summary)

    broken = tmp_path / "broken.json"
    broken.write_text('{"parameters": \n', encoding="utf-8")
    old = tmp_path / "old.json"
    old.write_text(json.dumps({k: v for k, v in summary.items() if k != "command"}), encoding="utf-8")
    no_sobol = tmp_path / "no_sobol.json"
    parameters = {k: v for k, v in summary["parameters"].items() if k != "sobol"}
    no_sobol.write_text(json.dumps({**summary, "parameters": parameters}), encoding="utf-8")
    for path, says in ((tmp_path / "missing.json", "no such"), (broken, "broken.json:2: not JSON"),
                       (old, "has no command"), (no_sobol, "parameters have no sobol")):
        target = tmp_path / f"{path.stem}.md"
        capsys.readouterr()
        assert main([str(path), str(target)]) == 2
        error = capsys.readouterr().err.strip()
        assert says in error and "\n" not in error, error
        assert not target.exists()


@pytest.mark.parametrize("page", ["faithfulness", "faithfulness-sobol"])
def test_the_docs_page_is_generated_from_its_json(page):
    """docs/results/PAGE.md is exactly the section generated from the study's summary stored beside it,
    docs/results/PAGE.json (robustness.json of the run the page names), and the results index lists it.
    Fails if a figure of the page is edited by hand (for example one digit of a percentile)."""
    from pathlib import Path

    results = Path(__file__).resolve().parent.parent / "docs" / "results"
    summary = json.loads((results / f"{page}.json").read_text(encoding="utf-8"))
    assert (results / f"{page}.md").read_text(encoding="utf-8") == faithfulness_markdown(summary)
    assert page in (results / "index.md").read_text(encoding="utf-8").split()
