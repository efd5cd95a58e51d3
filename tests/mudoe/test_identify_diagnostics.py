"""`mudoe identify` shows the curvature verdict and the weakest direction (issue 12, items 3-4)."""
import json

from mudoe.cli import main


def test_identify_prints_weakest_direction_and_curvature(capsys, campaign_dirs, tmp_path):
    out = tmp_path / "out"
    assert main(["identify", str(campaign_dirs["paper_cfg"]), "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "weakest direction (relative changes dp/|p|): " in text and "worse than" in text
    assert main(["identify", str(campaign_dirs["paper_cfg"]), "--out", str(out), "--json", "--quiet"]) == 0
    est = json.loads(capsys.readouterr().out)["M1"]
    wd, c = est["weakest_direction"], est["curvature"]
    assert wd["stderr_ratio"] > 1 and len(wd["sloppy"]) == len(est["params"])
    assert c["trustworthy"] is True and 0 <= c["parameter_effects"] < c["critical"]
    assert "worse than" in (out / "identify.txt").read_text()
