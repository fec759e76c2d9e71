"""The pipeline demo (simbench demo): scores, seeds in its table, and reruns from the render cache."""

import csv
import json

import pytest

from simbench.cache import RenderCache

pytestmark = pytest.mark.slow


def test_demo_rerun_takes_its_renders_from_the_cache_and_writes_the_same_results(tmp_path, variant, monkeypatch):
    from simbench.experiments import demo

    made = []
    original = RenderCache.get_or_make

    def counting(self, kind, parts, make):
        def tracked():
            made.append(kind)
            return make()

        return original(self, kind, parts, tracked)

    monkeypatch.setattr(RenderCache, "get_or_make", counting)
    cfg = demo.demo_config(spp=4, sampler="independent")
    kw = {"config": cfg, "scenes": ("white_plane",), "cache_dir": tmp_path / "cache", "progress": lambda s: None}
    demo.run_demo(tmp_path / "a", **kw)
    first = list(made)
    made.clear()
    demo.run_demo(tmp_path / "b", **kw)
    assert "radiance" in first and made == []
    assert (tmp_path / "a" / "metrics.json").read_bytes() == (tmp_path / "b" / "metrics.json").read_bytes()
    row = next(csv.DictReader((tmp_path / "b" / "summary.csv").read_text().splitlines()))
    seeds = json.loads((tmp_path / "b" / "metrics.json").read_text())["rows"][0]["seeds"]
    assert int(row["render_seed"]) == seeds["capture/white_plane"]["render"]
    assert float(row["gt_mae_mm"]) < 0.3 and float(row["completeness"]) > 0.99


def test_demo_summary_names_its_scenes_and_command_and_drops_old_figures(tmp_path, variant):
    """A second new user's audit: the summary's title was the four default scenes whatever ran,
    "Made by" dropped every option but --out, and a rerun with fewer scenes left the others'
    figures behind."""
    from simbench.cli import main

    out = tmp_path / "demo"
    base = ["demo", "--out", str(out), "--spp", "4", "--sampler", "independent", "--cache", str(tmp_path / "c")]
    assert main([*base, "--scenes", "white_plane", "tilted_plane"]) == 0
    assert (out / "tilted_plane.png").is_file()
    assert main([*base, "--scenes", "white_plane"]) == 0
    md = (out / "summary.md").read_text()
    assert md.startswith("# Pipeline demo: white plane\n"), md[:80]
    assert f"Made by `simbench demo --out {out} --spp 4 --sampler independent --scenes white_plane`" in md
    assert json.loads((out / "provenance.json").read_text())["command"].endswith("--scenes white_plane")
    assert not (out / "tilted_plane.png").exists() and (out / "white_plane.png").is_file()
