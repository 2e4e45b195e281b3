"""What-if grid keys for the study's unknowns (background_footprint, page_placement, memory_image, tree_variant)."""
from dataclasses import replace
from pathlib import Path

import pytest

from analyses.whatif import WHATIF_EXPERIMENT, WhatIf, configure, evaluate_point, parse_grid_flag
from analyses.whatif_grid import UNKNOWN_FIELDS, point_experiment
from coherence.unknowns import unknown

VARIANT = "d15-l32-box-longest-todepth-nearest"


@pytest.mark.parametrize("key, value, field", [
    ("background_footprint", 262144, "background_footprint"),
    ("page_placement", "bin-hopping", "page_placement"),
    ("memory_image", "malloc1997", "layout"),
    ("tree_variant", VARIANT, "tree_variant"),
])
def test_each_unknown_key_sets_the_experiment_field_it_names(key, value, field):
    """The point's Experiment is the base with that one field replaced, and configure's machine or layout takes
    it. Mutations: ``"memory_image": "cost"`` in UNKNOWN_FIELDS (the layout stays compact); drop
    ``background_footprint=experiment.background_footprint`` or ``page_placement=...`` from configure's Machine
    (the machine keeps its defaults, 1 MiB and contiguous)."""
    base = replace(WHATIF_EXPERIMENT, scene="tetra", size=8, workload="study1997")
    assert unknown(key).name == key and UNKNOWN_FIELDS[key] == field  # robustness's name for it
    assert getattr(base, field) != value
    assert point_experiment(base, {key: value, "memory_latency": 40}) == replace(base, **{field: value})
    study = WhatIf(name="t", experiment=base, grid={key: [value]})
    _, layout, _, machine, _ = configure(study, {key: value})
    configured = {"background_footprint": machine.background_footprint,
                  "page_placement": machine.page_placement.policy, "layout": layout.name}
    if field in configured:
        assert configured[field] == value
    else:
        assert (layout.name, machine.background_footprint) == ("compact", base.background_footprint)


def test_a_grid_flag_reads_sizes_and_names():
    """Mutation: drop ``*UNKNOWN_FIELDS`` from check_parameter (the keys are unknown what-if parameters)."""
    assert parse_grid_flag("background_footprint=96KB,4MB") == ("background_footprint", [98304, 4194304])
    assert parse_grid_flag("page_placement=contiguous,random") == ("page_placement", ["contiguous", "random"])
    assert parse_grid_flag(f"tree_variant={VARIANT}") == ("tree_variant", [VARIANT])
    assert parse_grid_flag("memory_image=alpha1997,malloc1997")[0] == "memory_image"


@pytest.mark.parametrize("grid, base, message", [
    ({"page_placement": ["striped"]}, {},
     "what-if parameter page_placement must be one of contiguous, colouring, bin-hopping, random, got 'striped'"),
    ({"memory_image": ["heap"]}, {}, "what-if parameter memory_image must be one of compact, alpha1997, malloc1997"),
    ({"tree_variant": ["d99"]}, {"workload": "study1997"}, "what-if parameter tree_variant must be one of d16-l32"),
    ({"background_footprint": [-1]}, {}, "what-if parameter background_footprint must be bytes, an integer >= 0"),
    ({"background_footprint": ["lots"]}, {}, "what-if parameter background_footprint must be bytes"),
    ({"tree_variant": [VARIANT]}, {}, f"what-if parameter tree_variant={VARIANT}: .*study1997"),
    ({"page_placement": ["random"]}, {"platform": "apple-m1"}, "what-if parameter page_placement=random: .*contiguous"),
    ({"memory_image": ["alpha1997"], "layout": ["compact"]}, {}, "memory_image and layout both set the memory layout"),
])
def test_bad_values_are_refused_naming_the_key_and_the_values(grid, base, message):
    """Refused when the study is made, before any trace. Mutations: drop the ``_UNKNOWN_CHOICES`` check (the
    Experiment's own message names no what-if parameter); drop the memory_image-beside-layout check (layout
    wins silently)."""
    with pytest.raises(ValueError, match=message):
        WhatIf.of("bad", grid, scene="tetra", size=8, **base)


def test_a_tree_variant_grid_renders_one_trace_per_variant(monkeypatch, tmp_path):
    """Each variant's points replay a trace rendered with that variant's tree. Mutation:
    ``tree_variant=base.tree_variant`` in whatif_traces.traces_for (every point replays the base's tree)."""
    import analyses.traces
    from analyses.whatif import _traces_for

    asked = []

    def fake(scene, size, **options):
        asked.append(options["tree_variant"])
        return None, None, {"path": str(tmp_path / options["tree_variant"])}

    monkeypatch.setattr(analyses.traces, "cached_trace", fake)
    base = WHATIF_EXPERIMENT.tree_variant
    study = WhatIf.of("trees", {"tree_variant": [base, VARIANT], "memory_latency": [40, 80]}, scene="tetra",
                      size=8, workload="study1997")
    folders = _traces_for(study, study.points(), tmp_path, False)
    assert asked == [base, VARIANT]
    assert {Path(folders[(None, name)]).parent.name for name in (base, VARIANT)} == {base, VARIANT}


def test_footprint_placement_and_image_reach_the_simulation(monkeypatch, tmp_path):
    """evaluate_point hands coherence.studies.study a machine with the point's footprint and page placement and
    the point's memory image. Mutations: ``layout = get_layout(point.get("layout", study.layout))`` in configure
    (the image stays compact); ``page_placement=PagePlacement()`` in configure's Machine."""
    import coherence.studies
    from analyses.traces import cached_trace

    class Simulated(Exception):
        pass

    def fake_study(trace, mappings, n_processes, **options):
        raise Simulated(options)

    _, _, info = cached_trace("tetra", 8, cache_dir=tmp_path, progress=False)
    monkeypatch.setattr(coherence.studies, "study", fake_study)
    study = WhatIf.of("t", {"background_footprint": [8192], "page_placement": ["colouring"],
                            "memory_image": ["alpha1997"]}, scene="tetra", size=8, page_seed=3)
    with pytest.raises(Simulated) as given:
        evaluate_point(study, study.points()[0], str(Path(info["path"]) / "trace"))
    options = given.value.args[0]
    machine = options["machine"]
    assert (machine.background_footprint, machine.page_placement.policy, machine.page_placement.seed) == \
        (8192, "colouring", 3)
    assert options["layout"].name == "alpha1997"
