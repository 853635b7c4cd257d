"""benchmarks/compare_metrics.py: two runs' metrics compared key by key, timings and machine facts apart."""

import json

from benchmarks.compare_metrics import compare, flatten, is_timing, main


BASE = {"case": "beam", "n_dofs": 100, "rows": [{"r": 2, "test_error": 0.125, "fit_seconds": 0.5,
                                                "cost": {"minimum": 1e-6, "q75": 2e-6}}],
        "machine": {"platform": "x"}, "seconds": {"total": 12.0}, "stable": True, "nan": float("nan")}


def test_paths_and_timings():
    flat = flatten(BASE)
    assert flat["rows/0/test_error"] == 0.125 and flat["rows/0/cost/q75"] == 2e-6
    assert is_timing("rows/0/fit_seconds") and is_timing("rows/0/cost/minimum") and is_timing("seconds/total")
    assert is_timing("machine/platform") and is_timing("reduced_model/all_pairs_ms_per_step")
    assert is_timing("control/0/realtime_factor")
    assert not is_timing("rows/0/test_error") and not is_timing("time_domain_error") and not is_timing("n_steps")


def test_numbers_within_the_tolerance_are_the_same_and_timings_are_not_compared():
    new = json.loads(json.dumps(BASE))
    new["rows"][0]["test_error"] = 0.125 * (1 + 1e-12)
    new["rows"][0]["fit_seconds"], new["seconds"]["total"], new["machine"]["platform"] = 0.7, 30.0, "y"
    report = compare(BASE, new)
    assert report["compared"] == 6 and report["timings"] == 5
    assert not (report["differing"] or report["missing"] or report["added"])
    assert report["max_at"] == "rows/0/test_error" and 0 < report["max_relative_difference"] < 1e-11


def test_differences_missing_and_added_keys_are_reported(tmp_path, capsys):
    new = json.loads(json.dumps(BASE))
    new["rows"][0]["test_error"] = 0.126
    new["stable"] = False
    del new["n_dofs"]
    new["extra"] = 1
    report = compare(BASE, new)
    assert [d[0] for d in report["differing"]] == ["rows/0/test_error", "stable"]
    assert report["missing"] == ["n_dofs"] and report["added"] == ["extra"]
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "metrics.json").write_text(json.dumps(BASE))
    (tmp_path / "b.json").write_text(json.dumps(new))
    assert main([str(tmp_path / "a"), str(tmp_path / "b.json")]) == 1
    out = capsys.readouterr().out
    assert "rows/0/test_error: 0.125 -> 0.126" in out and out.strip().endswith("different")
    assert main([str(tmp_path / "a"), str(tmp_path / "a" / "metrics.json")]) == 0
