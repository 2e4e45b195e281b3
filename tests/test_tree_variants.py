"""Tree variants of the study-era workload: the rules they build, the option, and the check against the study."""
import numpy as np
import pytest

from tracer.kd.tree import build_kdtree
from tracer.rendering.tree_variants import (PLAUSIBLE_TREE_VARIANTS, STUDY_TREE_VARIANT, TREE_VARIANTS,
                                            get_tree_variant, tree_rule_name, workload_with_tree)
from tracer.rendering.workload import STUDY_TREE, WORKLOADS
from tracer.scenes.model import Material, SceneBuilder


def _clustered_scene():
    """150 small spheres in a 12 x 6 x 4 box, a cluster of 60 overlapping ones that no plane separates,
    so a rule that splits to its depth limit reaches it there, and tight clusters of 32, 33, 48 and 49 (each
    leaf size and one more) in corners, so a node of exactly the leaf size, or one more, occurs."""
    rng = np.random.default_rng(29)
    b = SceneBuilder("clustered")
    b.material(Material((1.0, 1.0, 1.0), 1.0, 0.0, 1.0, 0.0, 1.0))
    for centre in rng.uniform((-6, -3, -2), (6, 3, 2), (150, 3)):
        b.sphere(centre, float(rng.uniform(0.05, 0.3)))
    for centre in rng.normal((1.3, 0.4, -0.2), 0.02, (60, 3)):
        b.sphere(centre, 0.3)
    for count, corner in zip((32, 33, 48, 49), ((-5.5, -2.5, -1.5), (5.5, -2.5, 1.5), (-5.5, 2.5, 1.5),
                                                (5.5, 2.5, -1.5))):
        for centre in rng.normal(corner, 0.01, (count, 3)):
            b.sphere(centre, 0.02)
    b.light((0.0, 0.0, 10.0))
    return b.build()


def _walk(tree):
    """Every node as (depth, box lo, box hi, axis or 3 for a leaf, its primitives), by hand from the root:
    the below child is the next node, the above child is in word 1; a node's primitives are its leaves'."""
    splits = tree.split_view[:, 0]
    out = {}

    def visit(node, depth, lo, hi):
        axis = int(tree.nodes[node, 1] & 3)
        if axis == 3:
            first, count = int(tree.nodes[node, 0]), int(tree.nodes[node, 1] >> 2)
            prims = set(tree.primitive_indices[first:first + count].tolist())
        else:
            split = float(splits[node])
            below_hi, above_lo = hi.copy(), lo.copy()
            below_hi[axis] = above_lo[axis] = split
            prims = visit(node + 1, depth + 1, lo, below_hi) | visit(int(tree.nodes[node, 1] >> 2), depth + 1,
                                                                    above_lo, hi)
        out[node] = (depth, lo, hi, axis, prims)
        return prims

    visit(0, 0, tree.bounds[0].astype(float), tree.bounds[1].astype(float))
    return list(out.values())


@pytest.mark.parametrize("name", list(TREE_VARIANTS))
def test_each_variant_builds_the_tree_its_rule_says(name):
    """Depth limit, leaf size and axis rule of the built tree, read node by node, are the name's.

    Fails when the registry reads a name wrong: checked by building the rule
    in ``tree_variants._rule`` with ``tree_depth=int(depth) - 1`` (the deepest
    leaf is one short), with ``leaf_size=int(leaf) + 1`` or ``- 1`` (a node
    of one more than the leaf size is left a leaf, or one of exactly the
    leaf size is split) and with ``axis_rule="cycle"`` for every name (the
    longest-axis variants split a shorter axis).
    """
    config = get_tree_variant(name)
    depth_limit, leaf_size = (int(part[1:]) for part in name.split("-")[:2])
    nodes = _walk(build_kdtree(_clustered_scene(), config))
    assert max(depth for depth, *_ in nodes) == depth_limit
    for depth, lo, hi, axis, prims in nodes:
        if axis == 3:  # a leaf: at most leaf_size primitives, unless the depth limit stopped it
            assert len(prims) <= leaf_size or depth == depth_limit
            continue
        assert len(prims) > leaf_size and depth < depth_limit
        extent = hi - lo
        if name.split("-")[3] == "cycle":
            assert axis == depth % 3
        else:
            assert extent[axis] == extent.max()


def test_names_spell_their_rules_and_the_default_is_the_study_tree():
    """The default variant is the study1997 workload's own tree, and each name reads back from its rule.

    Fails when the study tree and the default part: checked by changing
    ``STUDY_TREE``'s ``leaf_size`` from 32 to 48 in tracer/rendering/workload.py.
    """
    assert get_tree_variant(STUDY_TREE_VARIANT) == STUDY_TREE == WORKLOADS["study1997"].kd_config
    assert workload_with_tree("study1997", STUDY_TREE_VARIANT) is WORKLOADS["study1997"]
    assert workload_with_tree("study1997") is WORKLOADS["study1997"]
    assert PLAUSIBLE_TREE_VARIANTS[0] == STUDY_TREE_VARIANT
    assert set(PLAUSIBLE_TREE_VARIANTS) <= set(TREE_VARIANTS)
    for name, config in TREE_VARIANTS.items():
        assert tree_rule_name(config, WORKLOADS["study1997"].shadow_nearest) == name
        chosen = workload_with_tree("study1997", name)
        assert chosen.kd_config == config
        assert (chosen.name, chosen.shadow_nearest, chosen.log_ray_data) == ("study1997", True, True)


@pytest.mark.parametrize("call, words", [
    (lambda: get_tree_variant("d16-l32"), ["tree variant must be one of", *TREE_VARIANTS]),
    (lambda: workload_with_tree("study1997", "bsp"), ["tree variant must be one of", STUDY_TREE_VARIANT]),
    (lambda: workload_with_tree("modern", "d17-l48-box-cycle-todepth-nearest"), ["study1997 workload only"]),
    (lambda: workload_with_tree("nope", STUDY_TREE_VARIANT), ["workload must be one of"]),
])
def test_bad_names_are_refused_listing_the_choices(call, words):
    """Fails when an unknown name falls back to a default: checked by returning ``STUDY_TREE`` from
    ``get_tree_variant`` for a name not in the registry."""
    with pytest.raises(ValueError) as error:
        call()
    for word in words:
        assert word in str(error.value)


def test_the_modern_workload_keeps_its_tree_at_the_default_variant():
    """Fails when the default variant is refused on another workload: checked by removing
    ``or tree_variant == STUDY_TREE_VARIANT`` from ``workload_with_tree``'s first test."""
    assert workload_with_tree("modern", STUDY_TREE_VARIANT) is WORKLOADS["modern"]


def _check_script():
    """benchmarks/tree_variants.py, loaded as a module."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "tree_variants.py"
    spec = importlib.util.spec_from_file_location("tree_variants_check", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_check_reports_tests_against_the_study_and_tree_bytes():
    """Tetra at 8 x 8 with two variants: tests scaled to 512 x 512 over the study's, and the tree's bytes from
    its arrays with the alpha1997 image's 40-byte nodes and 16-byte index entries (docs/memory_image.md).

    Fails when the bytes or the scaling are wrong: checked by counting ``index_entries`` from
    ``tree.stats["leaves"]`` instead of ``tree.stats["references"]`` in benchmarks/tree_variants.py, and
    by scaling with ``STUDY_SIZE / size`` unsquared.
    """
    from tracer.rendering.render import RenderOptions, render
    from tracer.scenes.catalog import load

    check = _check_script()
    tetra = load("tetra")
    variants = [STUDY_TREE_VARIANT, "d15-l48-box-longest-todepth-nearest"]
    table = check.variant_table({"tetra": tetra}, [8], variants)
    assert list(table["variant"]) == variants and set(table["scene"]) == {"tetra"}
    for row in table.itertuples():
        workload = workload_with_tree("study1997", row.variant)
        tree = build_kdtree(tetra, workload.kd_config)
        assert (row.nodes, row.index_entries) == (len(tree.nodes), len(tree.primitive_indices))
        assert row.tree_bytes == 40 * len(tree.nodes) + 16 * len(tree.primitive_indices)
        walked = _walk(tree)
        assert row.depth == max(depth for depth, *_ in walked)
        tests = render(tetra, options=RenderOptions(size=8, log=False, workload=workload)).totals()
        scaled = tests["intersection_tests"] * 64 * 64 / 1e6
        assert row.tests_1e6 == pytest.approx(scaled, abs=1e-3)
        assert row.ratio == pytest.approx(scaled / 7.6, abs=1e-4)  # the study's 7.6 M tests of tetra


def test_plausible_keeps_variants_within_a_quarter_on_every_scene():
    """Hand-made ratios on the edge: 1.25 and 0.75 are inside, 1.26 and 0.74 outside, other sizes ignored.

    Fails when the bound is made strict: checked by changing ``<=`` to ``<`` in ``plausible``.
    """
    import pandas as pd

    check = _check_script()
    rows = [("a", "balls", 128, 1.25), ("a", "shell", 128, 0.75), ("b", "balls", 128, 1.0),
            ("b", "shell", 128, 1.26), ("c", "balls", 128, 0.74), ("c", "shell", 128, 1.0),
            ("d", "balls", 128, 1.0), ("d", "shell", 128, 1.0), ("d", "shell", 32, 2.0)]
    table = pd.DataFrame(rows, columns=["variant", "scene", "size", "ratio"])
    assert check.plausible(table, 128) == ["a", "d"]
    assert check.plausible(table, 32) == []


# the option: Experiment field, command line, trace cache


def test_the_experiment_holds_the_variant_and_records_it_where_it_builds_the_tree():
    """Default the study's rule; recorded for study1997, None for modern or another builder.

    Fails when the record ignores the workload: checked by returning ``self.tree_variant`` always from
    ``Experiment.tree_variant_used``.
    """
    from analyses.experiment import Experiment

    assert Experiment().tree_variant == STUDY_TREE_VARIANT
    assert Experiment().as_parameters()["tree_variant"] is None
    study = Experiment(scene="tetra", workload="study1997", tree_variant="d15-l48-box-longest-todepth-nearest")
    assert study.as_parameters()["tree_variant"] == "d15-l48-box-longest-todepth-nearest"
    assert Experiment(workload="study1997").as_parameters()["tree_variant"] == STUDY_TREE_VARIANT
    assert Experiment(workload="study1997", kd="sah").as_parameters()["tree_variant"] is None


@pytest.mark.parametrize("fields, words", [
    ({"workload": "study1997", "tree_variant": "d99"}, ["Experiment.tree_variant must be one of", *TREE_VARIANTS]),
    ({"tree_variant": "d17-l48-box-cycle-todepth-nearest"}, ["Experiment.tree_variant", "study1997 workload only"]),
    ({"workload": "study1997", "tree_variant": "d17-l48-box-cycle-todepth-nearest", "kd": "sah"},
     ["Experiment.kd must be None or median"]),
])
def test_the_experiment_refuses_a_bad_variant_naming_the_field(fields, words):
    """Fails when a variant is dropped silently: checked by deleting the ``workload_with_tree`` call of
    ``Experiment.__post_init__`` (modern takes any variant), and the kd check after it (sah takes one)."""
    from analyses.experiment import Experiment

    with pytest.raises(ValueError) as error:
        Experiment(**fields)
    for word in words:
        assert word in str(error.value)


def test_the_command_line_option_reaches_the_experiment_and_refuses_bad_names(capsys):
    """``--tree-variant`` sets the field; a bad name is refused listing the choices.

    Fails when the option is not mapped: checked by deleting ``"tree_variant": "tree_variant"`` from
    ``EXPERIMENT_OPTIONS``.
    """
    from analyses.cli import build_parser
    from analyses.commands.options import experiment_from_args

    parser = build_parser()
    args = parser.parse_args(["report", "tetra", "--workload", "study1997", "--tree-variant",
                              "d17-l32-box-cycle-todepth-nearest"])
    assert experiment_from_args(args).tree_variant == "d17-l32-box-cycle-todepth-nearest"
    assert experiment_from_args(parser.parse_args(["report", "tetra"])).tree_variant == STUDY_TREE_VARIANT
    with pytest.raises(SystemExit):
        parser.parse_args(["report", "tetra", "--tree-variant", "d16"])
    message = capsys.readouterr().err
    assert "--tree-variant" in message and all(name in message for name in TREE_VARIANTS)


def test_a_variant_gets_its_own_trace_key_and_tree(tmp_path):
    """balls at 4 x 4: the default's key is the key of before, a variant's key names it and differs, and
    its entry holds the variant's tree.

    Fails when the key ignores the variant: checked by leaving ``tree_variant=tree_variant`` out of
    ``cached_trace``'s call of ``trace_key`` (both entries get one key, and the second load returns the
    first tree).
    """
    from analyses.traces import cached_trace, trace_key

    variant = "d17-l48-box-cycle-todepth-nearest"
    _, _, default = cached_trace("balls", 4, cache_dir=tmp_path, progress=False, workload="study1997")
    _, _, other = cached_trace("balls", 4, cache_dir=tmp_path, progress=False, workload="study1997",
                               tree_variant=variant)
    assert default["key"] == trace_key("balls", 4, kd="median", max_depth=2, workload="study1997")
    assert variant not in default["key"] and variant in other["key"] and other["key"] != default["key"]
    assert not other["cached"]
    assert other["kd_config"] == TREE_VARIANTS[variant].to_dict() != default["kd_config"]
    assert other["tree"]["nodes"] != default["tree"]["nodes"]
    assert (other["tree_variant"], other["workload"]) == (variant, "study1997")
    with pytest.raises(ValueError, match="median tree; kd sah"):
        cached_trace("balls", 4, cache_dir=tmp_path, workload="study1997", tree_variant=variant, kd="sah")


class _Asked(Exception):
    pass


def _stop_at_the_trace(monkeypatch):
    """Make ``analyses.traces.cached_trace`` record its keyword arguments and stop the run there."""
    import analyses.traces

    asked = {}

    def fake(*args, **kwargs):
        asked.update(kwargs)
        raise _Asked

    monkeypatch.setattr(analyses.traces, "cached_trace", fake)
    return asked


def test_report_paper_and_whatif_pass_the_variant_to_the_trace(monkeypatch, tmp_path):
    """Fails when a command drops the variant: checked by deleting ``tree_variant=experiment.tree_variant``
    in analyses/report.py, ``tree_variant=one.tree_variant`` in analyses/paper.py and
    ``tree_variant=base.tree_variant`` in analyses/whatif_traces.py (each alone)."""
    from dataclasses import replace

    from analyses.experiment import Experiment
    from analyses.paper import reproduce
    from analyses.paper_study import PAPER_EXPERIMENT
    from analyses.report import build_report
    from analyses.whatif import WhatIf, _traces_for

    variant = "d15-l32-box-longest-todepth-nearest"
    asked = _stop_at_the_trace(monkeypatch)
    experiment = Experiment(scene="tetra", size=8, workload="study1997", tree_variant=variant, cache_dir=tmp_path,
                            dask="tcp://127.0.0.1:9", progress=False)
    with pytest.raises(_Asked):
        build_report(experiment)
    assert asked.pop("tree_variant") == variant
    with pytest.raises(_Asked):
        reproduce(replace(PAPER_EXPERIMENT, size=8, tree_variant=variant, cache_dir=tmp_path, progress=False),
                  scenes=["tetra"])
    assert asked.pop("tree_variant") == variant
    study = WhatIf.of("latency", {"memory_latency": [40, 80]}, scene="tetra", size=8, workload="study1997",
                      tree_variant=variant)
    with pytest.raises(_Asked):
        _traces_for(study, study.points(), tmp_path, False)
    assert asked.pop("tree_variant") == variant


def test_render_takes_the_variant_and_refuses_it_beside_kd():
    """``render --tree-variant`` builds the variant's workload; with ``--kd`` (which would build a default
    tree instead) it is refused.

    Fails when ``workload_from_args`` ignores the option: checked by returning ``get_workload(args.workload)``.
    """
    from analyses.cli import build_parser
    from analyses.commands.options import workload_from_args
    from rtcommon.validate import InputError

    parser = build_parser()
    args = parser.parse_args(["render", "balls", "--workload", "study1997", "--tree-variant",
                              "d17-l48-box-cycle-todepth-nearest"])
    assert workload_from_args(args).kd_config == TREE_VARIANTS["d17-l48-box-cycle-todepth-nearest"]
    assert workload_from_args(parser.parse_args(["render", "balls"])) is WORKLOADS["modern"]
    with pytest.raises(InputError, match="drop --kd median"):
        workload_from_args(parser.parse_args(["render", "balls", "--workload", "study1997", "--kd", "median",
                                              "--tree-variant", "d17-l48-box-cycle-todepth-nearest"]))


def test_the_documented_check_table_names_the_plausible_set():
    """docs/unknowns.md's tree-variant table marks exactly :data:`PLAUSIBLE_TREE_VARIANTS` plausible, each
    "yes" row within 25% of the study's on every scene at 128 x 128, and lists every registered variant.

    Fails when the registry and the measured table part: checked by keeping every variant in
    ``PLAUSIBLE_TREE_VARIANTS`` (d14, 1.27 on balls, becomes plausible).
    """
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "unknowns.md").read_text(encoding="utf-8")
    section = text[text.index("### tree_variant"):text.index("## Sources")]
    header = "| variant | balls 32 | balls 128 | tetra 32 | tetra 128 | shell 32 | shell 128 | plausible |"
    lines = section[section.index(header):].splitlines()[2:]
    rows = {}
    for line in lines:
        if not line.startswith("|"):
            break
        cells = [cell.strip().strip("`") for cell in line.strip("|").split("|")]
        rows[cells[0]] = cells
    assert list(rows) == list(TREE_VARIANTS)
    marked = [name for name, cells in rows.items() if cells[7] == "yes"]
    assert marked == list(PLAUSIBLE_TREE_VARIANTS)
    for name, cells in rows.items():
        inside = all(abs(float(cells[k]) - 1) <= 0.25 for k in (2, 4, 6))
        assert inside == (name in marked), name
