"""The first-run warm-up (analyses.warmup): a child compiles what the report then only loads."""
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numba
import pytest

from analyses import warmup
from analyses.traces import cached_trace

ROOT = Path(__file__).resolve().parent.parent


def test_synthetic_trace_has_the_array_types_of_a_cached_render(tmp_path):
    _, real, _ = cached_trace("balls", 4, cache_dir=tmp_path / "cache", progress=False)
    synthetic = warmup.synthetic_trace(tmp_path / "synthetic")
    for name in ("pixel_offsets", "records", "counters"):
        assert numba.typeof(getattr(synthetic, name)) == numba.typeof(getattr(real, name)), name
    assert synthetic.records.size > 0 and (synthetic.records >> 27 & 1).any()  # some writes among them


# Run in a fresh interpreter: the warm-up's steps, then a whole report. Every compiled function of the
# simulation's packages must already have the report's specialisations, or the warm-up compiled the wrong ones.
_SCRIPT = textwrap.dedent("""
    import json, sys
    from numba.core.dispatcher import Dispatcher
    from cachesim import get_hierarchy
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.mappings import DEFAULT_MAPPINGS, get_mapping
    from coherence.simulation import Machine
    from analyses.experiment import Experiment
    from analyses.report import build_report
    from analyses.warmup import _compile

    def signatures():
        found = {}
        for name, module in list(sys.modules.items()):
            if name.split(".")[0] in ("cachesim", "coherence", "analyses"):
                for attr, value in vars(module).items():
                    if isinstance(value, Dispatcher):
                        found[f"{value.py_func.__module__}.{value.py_func.__qualname__}"] = set(map(str, value.signatures))
        return found

    _compile(get_hierarchy("alpha21164"), get_layout("compact"), get_cost_model("alpha8400"),
             Machine(n_cpus=8, background_load=4), [get_mapping(m) for m in DEFAULT_MAPPINGS])
    before = signatures()
    build_report(Experiment("balls", 8, cache_dir=sys.argv[1], progress=False, n_processes=(1, 2)))
    after = signatures()
    print(json.dumps({name: sorted(sigs - before.get(name, set())) for name, sigs in after.items()
                      if sigs - before.get(name, set())}))
""")


@pytest.mark.jit_only
def test_the_report_compiles_nothing_the_warm_up_did_not(tmp_path):
    result = subprocess.run([sys.executable, "-c", _SCRIPT, str(tmp_path / "cache")], capture_output=True,
                            text=True, cwd=ROOT, check=True)
    assert json.loads(result.stdout.strip().splitlines()[-1]) == {}


@pytest.mark.jit_only
def test_the_child_runs_to_the_end(monkeypatch):
    from cachesim import get_hierarchy
    from coherence.cost import get_cost_model
    from coherence.layout import get_layout
    from coherence.mappings import get_mapping
    from coherence.simulation import Machine

    monkeypatch.setattr(warmup, "simulation_kernels_cached", lambda: False)
    with warmup.simulation_warm_up(get_hierarchy("alpha21164"), get_layout("compact"), get_cost_model("alpha8400"),
                                   Machine(), [get_mapping("S"), get_mapping("B")]) as warm:
        assert warm.process is not None
        assert warm.wait() == 0


def test_nothing_starts_when_disabled_or_cached(monkeypatch):
    monkeypatch.setattr(warmup, "simulation_kernels_cached", lambda: True)
    with warmup.simulation_warm_up(None, None, None, None, []) as warm:
        assert warm.process is None and warm.wait() is None
    monkeypatch.setattr(warmup, "simulation_kernels_cached", lambda: False)
    with warmup.simulation_warm_up(None, None, None, None, [], enabled=False) as warm:
        assert warm.process is None


def test_an_unpicklable_mapping_means_no_child(monkeypatch):
    monkeypatch.setattr(warmup, "simulation_kernels_cached", lambda: False)
    with warmup.simulation_warm_up(None, None, None, None, [lambda: None]) as warm:
        assert warm.process is None
