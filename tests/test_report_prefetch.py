"""``coherence report --platform NAME --prefetch on|off``: the platform's prefetchers from the command line."""
import json

from analyses.cli import main


def test_report_prefetch_switches_the_platforms_prefetchers(tmp_path, capsys):
    """``on`` runs the variant with prefetchers (L1 prefetches issued, named ``apple-m1[prefetch]`` in
    summary.json); ``off`` and no option give the platform as it is. Mutation: return ``platform`` instead of
    ``platform.variant(prefetch=...)`` in report's _platform (``on`` issues none)."""
    from analyses.cli import build_parser
    from analyses.commands.report import _platform
    from coherence.platforms import get_platform

    out = tmp_path / "on"
    assert main(["report", "tetra", "--size", "8", "--mappings", "P", "--processes", "4", "--platform", "apple-m1",
                 "--prefetch", "on", "--cache", str(tmp_path / "cache"), "--out", str(out)]) == 0, \
        capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["shared_levels"]["4"]["P"]["L1"]["prefetches_issued"] > 0
    assert summary["parameters"]["platform"]["name"] == "apple-m1[prefetch]"
    for switch in (["--prefetch", "off"], []):
        args = build_parser().parse_args(["report", "tetra", "--platform", "apple-m1", *switch])
        assert _platform(args) == get_platform("apple-m1") and not get_platform("apple-m1").hierarchy.hierarchy.prefetches


def test_report_prefetch_without_a_platform_is_an_error(tmp_path, capsys):
    """Refused before anything is rendered. Mutation: drop the ``args.prefetch is not None`` check in report's
    _platform (the option is ignored and the report runs)."""
    assert main(["report", "tetra", "--size", "8", "--prefetch", "on", "--out", str(tmp_path / "out"),
                 "--cache", str(tmp_path / "cache")]) == 2
    assert "--prefetch on switches a platform's prefetchers; give --platform NAME" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
