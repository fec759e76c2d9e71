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
