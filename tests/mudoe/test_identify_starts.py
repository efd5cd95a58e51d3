"""[identify] starts / seed: parsed, checked with file and line, passed to every fit; results.json (issue 30)."""
import json

import pytest

from mudoe.cli import main
from mudoe.config import ConfigError, IdentifyConfig, parse_config


def test_identify_section_defaults_and_values():
    assert parse_config("", "x.toml").identify == IdentifyConfig(starts=1, seed=0)
    cfg = parse_config("[identify]\nstarts = 8\nseed = 3\n", "x.toml")
    assert (cfg.identify.starts, cfg.identify.seed) == (8, 3)
    assert cfg.as_dict()["identify"] == {"starts": 8, "seed": 3}


@pytest.mark.parametrize("body, words", [
    ("starts = 0", "[identify] starts: must be at least 1, got 0"),
    ("starts = 2.5", "[identify] starts: expected an integer, got 2.5"),
    ("starts = true", "[identify] starts:"),
    ('starts = "3"', "[identify] starts:"),
    ("seed = -1", "[identify] seed: must be non-negative, got -1"),
    ("start = 3", "[identify] start: unknown key 'start'; allowed keys: seed, starts"),
])
def test_bad_identify_keys_name_file_line_and_key(body, words):
    with pytest.raises(ConfigError) as exc:
        parse_config(f"# a study\n[identify]\n{body}\n", "study.toml")
    msg = str(exc.value)
    assert msg.startswith("study.toml:3: ") and words in msg and "\n" not in msg


def test_bad_identify_key_exits_2_with_one_line(capsys, campaign_dirs):
    cfg = campaign_dirs["paper_cfg"]
    cfg.write_text(cfg.read_text() + "\n[identify]\nstarts = 0\n")
    assert main(["identify", str(cfg), "--out", str(campaign_dirs["root"] / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "paper.toml:" in err and "[identify] starts" in err


def test_identify_with_three_starts_end_to_end(capsys, campaign_dirs):
    """The tiny press study fitted from 3 starts: the estimate of one start equals the single fit (the problem
    has one minimum), every start is in identify.json."""
    cfg, out = campaign_dirs["paper_cfg"], campaign_dirs["root"] / "out"
    assert main(["identify", str(cfg), "--out", str(out / "one"), "--json", "--quiet"]) == 0
    one = json.loads(capsys.readouterr().out)["M1"]
    assert "multistart" not in one
    cfg.write_text(cfg.read_text() + "\n[identify]\nstarts = 3\nseed = 4\n")
    assert main(["identify", str(cfg), "--out", str(out / "three"), "--json", "--quiet"]) == 0
    three = json.loads(capsys.readouterr().out)["M1"]
    ms = three["multistart"]
    assert ms["n_starts"] == 3 and len(ms["objective"]) == 3 and ms["starts"][0] == [500.0, 500.0]
    assert ms["best"] == 1 and three["p"] == one["p"]            # p0 reaches the global minimum: bit for bit
    assert sum(len(m["starts"]) for m in ms["minima"]) == ms["outcome"].count("minimum")
    assert ms["minima"][0]["objective"] == pytest.approx(one["objective"], rel=1e-12)
