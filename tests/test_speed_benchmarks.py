"""The PSF-field speed benchmark runs (quick mode) and reports sane figures."""

import importlib.util
import json
from pathlib import Path


def test_psf_field_speed_quick(tmp_path):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "psf_field_speed.py"
    spec = importlib.util.spec_from_file_location("psf_field_speed", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.main(["--quick", "--out", str(tmp_path / "r.json")])
    assert (tmp_path / "r.json").exists()
    for case in res["cases"].values():
        assert 0 < case["seconds_best"] < 30
        assert case["psf_extent_px"][1] >= case["psf_extent_px"][0] >= 1


def test_deconv_speed_quick(tmp_path):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "deconv_speed.py"
    spec = importlib.util.spec_from_file_location("deconv_speed", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "d.json"
    assert mod.main(["--quick", "--out", str(out)]) in (0, None)
    assert out.exists() and json.loads(out.read_text())


def test_wiener_oracle_quick(tmp_path, shared_data):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "wiener_oracle.py"
    spec = importlib.util.spec_from_file_location("wiener_oracle", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.main(["--quick", "--out", str(tmp_path / "o.json")])
    saved = json.loads((tmp_path / "o.json").read_text())
    assert res["cases"] == 2 and saved["machine"]["cpu_count"] >= 1
    assert res["mean_psnr"]["oracle_psnr"] >= res["mean_psnr"]["wiener_psnr"]
