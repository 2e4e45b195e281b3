"""Textures: (u, v) mapping, mip levels, filtering, texel layouts and an exact replay of a textured trace."""
import math

import numpy as np
import pandas as pd
import pytest

from cachesim.config import get_hierarchy
from cachesim.simulate import simulate
from coherence.layout import get_layout
from coherence.studies import place_layout
from coherence.texture_layout import TextureLayout
from reference_cache import reference_simulate
from tracer.trace.records import Counter, RecordKind, make_record, pack, unpack
from tracer.scenes.model import Material, SceneBuilder
from tracer.rendering.texture import MipChains, TextureFilter, filtered_lookup, halve, mip_chains, procedural_texture
from tracer.kd.traverse import RecordLog
from tracer.rendering.uv import surface_uv, uv_maps


# ---------------------------------------------------------------- (u, v) and density

def _geometry(scene):
    from tracer.rendering.geometry import prepare_geometry
    return prepare_geometry(scene)


def test_sphere_uv_by_hand():
    b = SceneBuilder()
    b.material(Material(texture=b.texture(procedural_texture(4))))
    b.sphere((1.0, 2.0, 3.0), 2.0)
    scene = b.build()
    maps, geo = uv_maps(scene), _geometry(scene)
    assert surface_uv(0, 0, 0, geo, maps, 3.0, 2.0, 3.0) == pytest.approx((0.5, 0.5))   # +x
    assert surface_uv(0, 0, 0, geo, maps, 1.0, 4.0, 3.0) == pytest.approx((0.75, 0.5))  # +y
    assert surface_uv(0, 0, 0, geo, maps, 1.0, 2.0, 5.0)[1] == pytest.approx(1.0)       # north pole
    assert surface_uv(0, 0, 0, geo, maps, 1.0, 2.0, 1.0)[1] == pytest.approx(0.0)       # south pole
    assert maps.density[0] == pytest.approx(1.0 / (16.0 * math.pi))


def test_triangle_and_rectangle_uv_by_hand():
    b = SceneBuilder()
    b.material(Material(texture=b.texture(procedural_texture(4))))
    b.triangle([(0, 0, 0), (2, 0, 0), (0, 2, 0)], uv=[(0, 0), (1, 0), (0, 1)])
    b.polygon([(0, 0, 1), (4, 0, 1), (4, 0, 3), (0, 0, 3)], uv=[(0, 0), (2, 0), (2, 1), (0, 1)])
    scene = b.build()
    maps, geo = uv_maps(scene), _geometry(scene)
    assert surface_uv(1, 0, 0, geo, maps, 0.5, 1.0, 0.0) == pytest.approx((0.25, 0.5))
    assert maps.density[0] == pytest.approx(0.25)  # (u, v) area 1/2 over 2 units of area
    assert surface_uv(2, 1, 0, geo, maps, 3.0, 0.0, 2.0) == pytest.approx((1.5, 0.5))
    assert maps.density[1] == pytest.approx(2.0 / 8.0)


def test_textured_element_without_uv_is_an_error():
    b = SceneBuilder()
    b.material(Material(texture=b.texture(procedural_texture(4))))
    b.triangle([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    with pytest.raises(ValueError, match="element 0 .*no \\(u, v\\)"):
        uv_maps(b.build())


def test_material_texture_must_exist():
    b = SceneBuilder()
    b.material(Material(texture=0))
    with pytest.raises(ValueError, match="texture 0"):
        b.sphere((0, 0, 0), 1)
    with pytest.raises(ValueError, match="uv_scale"):
        Material(uv_scale=0.0)


# ---------------------------------------------------------------- mip chains

def test_halve_by_hand():
    image = np.zeros((3, 3, 4), np.uint8)
    image[..., 0] = [[0, 10, 20], [30, 40, 50], [60, 70, 80]]
    out = halve(image)
    assert out.shape == (1, 1, 4)
    assert out[0, 0, 0] == 20  # (0 + 10 + 30 + 40 + 2) // 4
    wide = np.zeros((1, 4, 4), np.uint8)
    wide[0, :, 1] = [1, 2, 3, 5]
    assert halve(wide)[0, :, 1].tolist() == [2, 4]  # (1+2+1+2+2)//4, (3+5+3+5+2)//4


def test_mip_chain_levels_and_numbering():
    b = SceneBuilder()
    b.texture(procedural_texture(8, 4, seed=1))
    b.texture(procedural_texture(3, seed=2))
    chains = mip_chains(b.build())
    assert chains.levels() == [[[8, 4], [4, 2], [2, 1], [1, 1]], [[3, 3], [1, 1]]]
    assert chains.level_first.tolist() == [0, 32, 40, 42, 43, 52, 53]


# ---------------------------------------------------------------- filtered lookups

def _reference_lookup(levels, u, v, detail, mode):
    """Colour and texel reads (level, x, y) of a lookup, by the rules of tracer.rendering.texture, in plain Python."""
    coarsest = len(levels) - 1
    level = min(max(detail, 0.0), coarsest)

    def texel(k, x, y):
        reads.append((k, x, y))
        return levels[k][y, x, :3].astype(float) / 255.0

    def bilinear(k):
        h, w = levels[k].shape[:2]
        fx = (u % 1.0) * w - 0.5
        fy = (1.0 - v % 1.0) * h - 0.5
        x0, y0 = math.floor(fx), math.floor(fy)
        ax, ay = fx - x0, fy - y0
        xa, ya = x0 % w, y0 % h
        xb, yb = (xa + 1) % w, (ya + 1) % h
        c = [texel(k, xa, ya), texel(k, xb, ya), texel(k, xa, yb), texel(k, xb, yb)]
        return ((1 - ax) * (1 - ay) * c[0] + ax * (1 - ay) * c[1] + (1 - ax) * ay * c[2] + ax * ay * c[3])

    reads = []
    if mode == TextureFilter.TRILINEAR:
        finer = math.floor(level)
        colour = bilinear(finer)
        if level > finer:
            colour = colour + (level - finer) * (bilinear(finer + 1) - colour)
        return colour, reads
    k = math.floor(level + 0.5)
    if mode == TextureFilter.BILINEAR:
        return bilinear(k), reads
    h, w = levels[k].shape[:2]
    return texel(k, min(int((u % 1.0) * w), w - 1), min(int((1.0 - v % 1.0) * h), h - 1)), reads


def _lookup(chains, texture, u, v, detail, mode):
    records = np.zeros(64, np.uint32)
    counters = np.zeros(len(Counter), np.int64)
    r, g, b, pos = filtered_lookup(chains, texture, u, v, detail, int(mode), RecordLog(records, 64), 0, counters)
    return np.array([r, g, b]), records[:pos], counters


@pytest.mark.parametrize("mode", list(TextureFilter))
def test_filtered_lookups_equal_the_reference(mode):
    rng = np.random.default_rng(int(mode))
    b = SceneBuilder()
    b.texture(procedural_texture(5, 3, seed=7))
    b.texture(procedural_texture(16, 8, seed=8))
    scene = b.build()
    chains = mip_chains(scene)
    for texture in range(2):
        levels = [chains.texels[chains.level_first[k]:chains.level_first[k + 1]]
                  .reshape(chains.level_height[k], chains.level_width[k], 4)
                  for k in range(chains.texture_level[texture], chains.texture_level[texture + 1])]
        first_level = chains.texture_level[texture]
        for _ in range(200):
            u, v = rng.uniform(-3, 3, 2)
            detail = rng.uniform(-1, len(levels) + 1)
            colour, records, counters = _lookup(chains, texture, u, v, detail, mode)
            expected, reads = _reference_lookup(levels, u, v, detail, mode)
            np.testing.assert_allclose(colour, expected, rtol=1e-12, atol=1e-12)
            kinds, ids = unpack(records)
            assert kinds[0] == RecordKind.TEXTURE and ids[0] == texture
            numbers = [chains.level_first[first_level + k] + y * chains.level_width[first_level + k] + x
                       for k, x, y in reads]
            assert kinds[1:].tolist() == [RecordKind.TEXEL] * len(reads)
            assert ids[1:].tolist() == numbers
            assert counters[Counter.TEXTURE_LOOKUPS] == 1 and counters[Counter.TEXEL_READS] == len(reads)


def test_level_selection_by_hand():
    b = SceneBuilder()
    b.texture(procedural_texture(8, seed=3))  # levels 8, 4, 2, 1 texels: texel numbers 0, 64, 80, 84
    chains = mip_chains(b.build())

    def levels_read(detail, mode):
        _, records, _ = _lookup(chains, 0, 0.3, 0.6, detail, mode)
        firsts = chains.level_first
        return sorted({int(np.searchsorted(firsts, i, side="right") - 1) for i in unpack(records)[1][1:]})

    assert levels_read(0.4, TextureFilter.NEAREST) == [0]
    assert levels_read(0.6, TextureFilter.NEAREST) == [1]
    assert levels_read(-5.0, TextureFilter.BILINEAR) == [0]
    assert levels_read(9.0, TextureFilter.BILINEAR) == [3]
    assert levels_read(1.5, TextureFilter.TRILINEAR) == [1, 2]
    assert levels_read(2.0, TextureFilter.TRILINEAR) == [2]  # on a level: that level only
    assert levels_read(7.0, TextureFilter.TRILINEAR) == [3]


# ---------------------------------------------------------------- texel layouts

def _reference_order(layout, w, h):
    """Memory position of each texel (row-major index), built by walking memory in order."""
    position = {}
    counter = 0

    def visit(x, y):
        nonlocal counter
        if x < w and y < h:
            position[y * w + x] = counter
        counter += 1

    if layout.order == "linear":
        for y in range(h):
            for x in range(w):
                visit(x, y)
    elif layout.order == "tiled":
        t = layout.tile
        for ty in range(0, h, t):
            for tx in range(0, w, t):
                for y in range(ty, ty + t):
                    for x in range(tx, tx + t):
                        visit(x, y)
    elif layout.order == "blocked":
        t, s = layout.tile, layout.superblock
        side = t * s
        for sy in range(0, h, side):
            for sx in range(0, w, side):
                for by in range(sy, sy + side, t):
                    for bx in range(sx, sx + side, t):
                        for y in range(by, by + t):
                            for x in range(bx, bx + t):
                                visit(x, y)
    else:  # morton: squares of the shorter power-of-two side along the longer one, each in Z order
        pw, ph = 1 << (w - 1).bit_length(), 1 << (h - 1).bit_length()
        square = min(pw, ph)

        def z(x0, y0, size):
            if size == 1:
                visit(x0, y0)
                return
            half = size // 2
            for dy in (0, half):
                for dx in (0, half):
                    z(x0 + dx, y0 + dy, half)

        for k in range(max(pw, ph) // square):
            if pw > ph:
                z(k * square, 0, square)
            else:
                z(0, k * square, square)
    return np.array([position[i] for i in range(w * h)]), counter


LAYOUTS = [TextureLayout("linear"), TextureLayout("tiled", tile=4), TextureLayout("tiled", tile=2),
           TextureLayout("morton"), TextureLayout("blocked", tile=4, superblock=2),
           TextureLayout("blocked", tile=2, superblock=4)]


@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda layout: layout.label)
@pytest.mark.parametrize("w, h", [(8, 8), (16, 4), (4, 16), (5, 3), (1, 1), (13, 7)])
def test_level_order_equals_a_walk_through_memory(layout, w, h):
    expected, size = _reference_order(layout, w, h)
    assert layout.level_order(w, h).tolist() == expected.tolist()
    assert layout.level_texels(w, h) == size


@pytest.mark.parametrize("layout", LAYOUTS, ids=lambda layout: layout.label)
def test_texel_offsets_chain_every_level_and_never_collide(layout):
    textures = [[(8, 4), (4, 2), (2, 1), (1, 1)], [(3, 3), (1, 1)]]
    offsets = layout.texel_offsets(textures)
    assert offsets.shape == (32 + 8 + 2 + 1 + 9 + 1,)
    assert len(set(offsets.tolist())) == offsets.size
    start = 0
    for (w, h), first in zip([(8, 4), (4, 2), (2, 1), (1, 1), (3, 3), (1, 1)], [0, 32, 40, 42, 43, 52]):
        assert offsets[first:first + w * h].tolist() == (start + layout.level_order(w, h)).tolist()
        start += layout.level_texels(w, h)


def test_by_level_chains_put_every_level_0_first():
    layout = TextureLayout("linear", chains="by_level")
    offsets = layout.texel_offsets([[(2, 2), (1, 1)], [(4, 1), (2, 1), (1, 1)]])
    # texture 0: level 0 at 0..3, level 1 at 8; texture 1: level 0 at 4..7, level 1 at 9..10, level 2 at 11
    assert offsets.tolist() == [0, 1, 2, 3, 8, 4, 5, 6, 7, 9, 10, 11]


def test_texture_layout_validation():
    with pytest.raises(ValueError, match="order"):
        TextureLayout("hilbert")
    with pytest.raises(ValueError, match="tile"):
        TextureLayout("tiled", tile=3)
    with pytest.raises(ValueError, match="chains"):
        TextureLayout(chains="mixed")


def test_memory_layout_places_texels_by_its_texture_layout():
    layout = get_layout("compact").with_texels(TextureLayout("tiled", tile=2))
    placed = layout.place({"texel": 16, "texture": 1}, textures=[[(4, 4)]])
    texels = placed.record_start[placed.kind_first[RecordKind.TEXEL]:placed.kind_first[RecordKind.TEXEL + 1]]
    base = int(texels.min())
    # texel (2, 0) (row-major number 2) starts the second 2 x 2 tile: 4 texels of 4 bytes in
    assert texels[2] - base == 16 and texels[4] - base == 8
    with pytest.raises(ValueError, match="textures"):
        layout.place({"texel": 16})
    with pytest.raises(ValueError, match="17 texels"):
        layout.place({"texel": 17}, textures=[[(4, 4)]])


# ---------------------------------------------------------------- rendering and replay

def _small_textured_scene():
    from tracer.scenes.textured import balls_textured

    scene = balls_textured(floor_size=64, sphere_size=32)
    scene.max_depth = 2
    return scene


def test_textured_render_logs_texels_and_counts_them():
    from tracer.rendering.render import RenderOptions, render

    scene = _small_textured_scene()
    results = {mode: render(scene, options=RenderOptions(size=24, texture_filter=mode))
               for mode in ("nearest", "bilinear", "trilinear")}
    for result in results.values():
        kinds, _ = unpack(result.trace.records)
        totals = result.totals()
        assert totals["texel_reads"] == np.count_nonzero(kinds == RecordKind.TEXEL) > 0
        assert totals["texture_lookups"] == np.count_nonzero(kinds == RecordKind.TEXTURE)
        assert result.trace.metadata["textures"][0][0] == [64, 64]
    lookups = results["nearest"].totals()["texture_lookups"]
    assert results["bilinear"].totals()["texel_reads"] == 4 * lookups
    assert 4 * lookups < results["trilinear"].totals()["texel_reads"] <= 8 * lookups
    # the same rays whatever the filter; the texture changes the picture
    assert results["nearest"].totals()["primary_hits"] == results["trilinear"].totals()["primary_hits"]
    from tracer.scenes.spd import balls
    plain = balls()
    plain.max_depth = 2
    assert not np.allclose(render(plain, options=RenderOptions(size=24, log=False)).image, results["trilinear"].image)


@pytest.mark.parametrize("order", ["linear", "morton", "blocked"])
def test_textured_trace_replays_exactly_through_cachesim(order):
    from tracer.rendering.render import RenderOptions, render

    scene = _small_textured_scene()
    trace = render(scene, options=RenderOptions(size=12)).trace
    layout = get_layout("compact").with_texels(TextureLayout(order, tile=4, superblock=2))
    placed = place_layout(layout, trace, scene)
    addresses = placed.addresses(trace.records, 32)
    # by hand: every texel record's address is its layout position times 4 bytes from the region start
    kinds, ids = unpack(trace.records)
    offsets = layout.texels.texel_offsets(trace.metadata["textures"])
    texel_rows = placed.kind_first[RecordKind.TEXEL] + ids[kinds == RecordKind.TEXEL]
    region = placed.record_start[placed.kind_first[RecordKind.TEXEL]:placed.kind_first[RecordKind.TEXEL + 1]].min()
    assert np.array_equal(placed.record_start[texel_rows] - region, 4 * offsets[ids[kinds == RecordKind.TEXEL]])
    hierarchy = get_hierarchy("alpha21164")
    got = simulate(addresses, hierarchy).counts
    expected, _ = reference_simulate(addresses, hierarchy)
    assert np.array_equal(got, expected)


def test_texel_records_pack_to_their_global_numbers():
    assert pack([RecordKind.TEXEL], [12345])[0] == make_record(RecordKind.TEXEL, 12345)
    assert isinstance(mip_chains(SceneBuilder().build()), MipChains)


# ---------------------------------------------------------------- misses by kind and the texture what-if

def test_misses_by_kind_equal_a_plain_replay_per_process():
    from cachesim.config import Hierarchy
    from coherence.kind_misses import misses_by_kind, texture_summary
    from coherence.mappings import get_mapping
    from tracer.rendering.render import RenderOptions, render

    scene = _small_textured_scene()
    trace = render(scene, options=RenderOptions(size=12)).trace
    placed = place_layout(get_layout("compact").with_texels(TextureLayout("morton")), trace, scene)
    base = get_hierarchy("alpha21164")
    hierarchy = Hierarchy(tuple(replace_size(level, level.size // 32) for level in base.levels),
                          memory_latency=base.memory_latency)
    distribution = get_mapping("R").build(12, 12, 3)
    table = misses_by_kind(trace, placed, hierarchy, distribution)
    n_levels = len(hierarchy.levels)
    accesses = np.zeros((n_levels, len(RecordKind)), np.int64)
    misses = np.zeros_like(accesses)
    for process in range(3):
        addresses, kinds = [], []
        for row in range(process, 12, 3):  # R: rows round-robin, each left to right
            for pixel in range(12 * row, 12 * row + 12):
                for record in trace.records[trace.pixel_offsets[pixel]:trace.pixel_offsets[pixel + 1]]:
                    kind, index = int(record) >> 28, int(record) & ((1 << 27) - 1)
                    start = int(placed.record_start[placed.kind_first[kind] + index])
                    size = int(placed.record_size[placed.kind_first[kind] + index])
                    for line in range(start // 32, (start + size - 1) // 32 + 1):
                        addresses.append(line * 32)
                        kinds.append(kind)
        _, served = reference_simulate(addresses, hierarchy)
        for kind, level_served in zip(kinds, served):
            for level in range(min(level_served, n_levels - 1) + 1):
                accesses[level, kind] += 1
                misses[level, kind] += level_served > level
    for row in table.itertuples():
        level = [lv.name for lv in hierarchy.levels].index(row.level)
        kind = RecordKind[row.kind.upper()]
        assert (row.accesses, row.misses) == (accesses[level, kind], misses[level, kind]), row
    assert table["accesses"].sum() == accesses.sum()
    summary = texture_summary(table)
    texel = table[(table["level"] == "L1") & (table["kind"] == "texel")]
    assert summary["texel_L1_misses_per_access"] == pytest.approx(float(texel["misses"].iloc[0] / texel["accesses"].iloc[0]))


def replace_size(level, size):
    from dataclasses import replace

    return replace(level, size=size)


def test_texture_whatif_runs_on_a_small_image(tmp_path):
    from dataclasses import replace

    from analyses.whatif import BUILTIN, run_whatif, save_whatif

    texture = BUILTIN["texture"]
    study = replace(texture, experiment=replace(texture.experiment, size=16, mappings=("S", "DB")),
                    grid={"texture_layout": ["linear", "morton"], "L1.size": [8192]})
    table = run_whatif(study, cache_dir=tmp_path / "cache", n_jobs=1, progress=False)
    assert len(table) == 4
    rates = table["texel_L1_misses_per_access"]
    assert ((rates > 0) & (rates <= 1)).all()
    assert ((table["texture_L1_miss_share"] > 0) & (table["texture_L1_miss_share"] < 1)).all()
    (tmp_path / "out").mkdir()
    csv, png = save_whatif(table, study, tmp_path / "out")
    assert csv.exists() and png.exists()


def test_misses_per_layout_equal_one_layout_at_a_time():
    from coherence.kind_misses import misses_by_kind, misses_by_kind_per_layout
    from coherence.mappings import get_mapping
    from tracer.rendering.render import RenderOptions, render

    scene = _small_textured_scene()
    trace = render(scene, options=RenderOptions(size=12)).trace
    hierarchy = get_hierarchy("alpha21164")
    placements = {label: place_layout(get_layout("compact").with_texels(TextureLayout.from_label(label)), trace, scene)
                  for label in ("linear", "morton", "blocked2x2")}
    # a placement that moves more than texels (bigger spheres) takes the full path
    placements["alpha1997"] = place_layout(get_layout("alpha1997"), trace, scene)
    distribution = get_mapping("B").build(12, 12, 4)
    together = misses_by_kind_per_layout(trace, placements, hierarchy, distribution)
    for label, placed in placements.items():
        alone = misses_by_kind(trace, placed, hierarchy, distribution)
        mine = together[together["layout"] == label].drop(columns="layout").reset_index(drop=True)
        pd.testing.assert_frame_equal(mine, alone)
    texel_l1 = together[(together["kind"] == "texel") & (together["level"] == "L1")].set_index("layout")["misses"]
    assert texel_l1["linear"] != texel_l1["morton"]  # the order matters to texel misses


def test_report_texture_section_tables():
    from analyses.report_texture import LAYOUTS, texture_section
    from coherence.cost import get_cost_model
    from coherence.mappings import get_mapping
    from tracer.rendering.render import RenderOptions, render

    scene = _small_textured_scene()
    trace = render(scene, options=RenderOptions(size=12)).trace
    section = texture_section(trace, scene, get_layout("compact"), get_hierarchy("alpha21164"),
                              [get_mapping("S"), get_mapping("DB")], 4, get_cost_model("alpha8400"))
    share, layouts, curves = section["share"], section["layouts"], section["curves"]
    assert set(share["mapping"]) == {"S", "DB"} and len(share) == 2 * 3
    l1 = share[share["level"] == "L1"]
    assert (l1["texel_reads"] == render(scene, options=RenderOptions(size=12, log=False)).totals()["texel_reads"]).all()
    assert ((share["texture_miss_share"] > 0) & (share["texture_miss_share"] <= 1)).all()
    assert list(dict.fromkeys(layouts["layout"])) == list(LAYOUTS)
    linear = layouts[(layouts["layout"] == "linear")].reset_index(drop=True)
    assert np.allclose(linear["texel_hit_rate"], 1 - share["misses_per_texel_read"])
    assert (np.diff(curves[curves["layout"] == "morton"]["misses"]) <= 0).all()  # LRU curves never rise


def test_render_cli_reports_texture_lookups_for_its_filter():
    import json
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "analyses", "render", "balls-textured", "--size", "8", "--no-log",
                           "--texture-filter", "nearest", "--json"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    textures = json.loads(done.stdout)["textures"]
    assert textures["filter"] == "nearest" and textures["texel_reads"] == textures["lookups"] > 0
    plain = subprocess.run([sys.executable, "-m", "analyses", "render", "tetra", "--size", "4", "--no-log", "--json"],
                           capture_output=True, text=True)
    assert "textures" not in json.loads(plain.stdout)


def test_report_of_a_textured_scene_has_the_texture_section(tmp_path):
    import json

    from analyses.cli import main
    from analyses.report import SECTIONS

    out = tmp_path / "out"
    assert main(["report", "balls-textured", "--size", "12", "--processes", "2", "--mappings", "S", "B",
                 "--out", str(out), "--cache", str(tmp_path / "cache")]) == 0
    results = pd.read_csv(out / "results.csv")
    for section in ("texture", "texture_layouts", "texture_miss_ratio"):
        assert section in SECTIONS and (results["section"] == section).any(), section
    share = results[(results["section"] == "texture") & (results["metric"] == "texture_miss_share")]
    assert ((share["value"] > 0) & (share["value"] <= 1)).all() and len(share) == 2 * 3
    page = (out / "index.html").read_text()
    assert "<h2>Textures</h2>" in page and "<h2>Misses per pixel" in page
    summary = json.loads((out / "summary.json").read_text())
    assert summary["parameters"]["texture"]["textures"][0][0] == [2048, 2048]


def test_textured_paper_scenes_round_trip_through_nff(tmp_path):
    from tracer.scenes.nff import read_nff, write_nff
    from tracer.scenes.model import scenes_equal
    from tracer.scenes.textured import balls_textured, room_textured

    for scene in (balls_textured(floor_size=64, sphere_size=32), room_textured(floor_size=32, wall_size=16)):
        path = tmp_path / f"{scene.name}.nff"
        write_nff(scene, path)
        back = read_nff(path, max_depth=scene.max_depth)
        assert scenes_equal(scene, back), scene.name
        # every material row is used, numbered by first use
        first = np.unique(scene.element_material, return_index=True)[1]
        assert np.array_equal(np.sort(first), first) and first.size == scene.material_kd.size


def test_the_texel_order_moves_no_other_record():
    counts = {kind: 5 for kind in RecordKind}
    textures = [[(6, 6), (3, 3), (1, 1)]]
    counts[RecordKind.TEXEL] = 36 + 9 + 1
    placed = {label: get_layout("compact").with_texels(TextureLayout.from_label(label)).place(counts, textures=textures)
              for label in ("linear", "tiled4", "morton", "blocked4x8")}
    lo = placed["linear"].kind_first[RecordKind.TEXEL]
    hi = placed["linear"].kind_first[RecordKind.TEXEL + 1]
    for label, other in placed.items():
        assert np.array_equal(other.record_start[:lo], placed["linear"].record_start[:lo]), label
        assert np.array_equal(other.record_start[hi:], placed["linear"].record_start[hi:]), label
        # texels come after every other region
        assert other.record_start[lo:hi].min() > np.delete(other.record_start, np.arange(lo, hi)).max()
