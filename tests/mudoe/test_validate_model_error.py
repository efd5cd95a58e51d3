"""``mudoe validate`` reports the held-out coverage of the validated variant's bands with and without its model
error (issue 29, item 4), as ``mudoe quantify`` computes it; ``--no-model-error`` / ``[validate] model_error``."""
import io
import json
from contextlib import redirect_stdout
from pathlib import Path

import pytest

from cli_texts import one_line_error
from mudoe.cli import main

REPO = Path(__file__).resolve().parents[2]
CSTR = REPO / "configs" / "cstr.toml"
PRESS = REPO / "configs" / "press.toml"


def _validate(*argv) -> tuple:
    """(exit code, validate.json, validate.txt) of ``mudoe validate ARGV --runs 2 --quiet --json``."""
    out = Path(argv[argv.index("--out") + 1])
    buf = io.StringIO()
    with redirect_stdout(buf):
        rc = main(["validate", *argv, "--runs", "2", "--quiet", "--json"])
    d = json.loads((out / "validate.json").read_text()) if rc == 0 else None
    assert rc != 0 or json.loads(buf.getvalue()) == d
    return rc, d, (out / "validate.txt").read_text() if rc == 0 else ""


def _own_cstr(tmp_path: Path, extra: str) -> Path:
    """configs/cstr.toml with its data folder made absolute and ``extra`` appended to its [validate] section."""
    text = CSTR.read_text().replace('directory = "../data/cstr"', f'directory = "{REPO / "data" / "cstr"}"')
    text = text.replace("[validate]\nn_runs = 20\n", f"[validate]\nn_runs = 20\n{extra}\n")
    cfg = tmp_path / "cstr.toml"
    cfg.write_text(text)
    return cfg


def test_an_adequate_variant_gets_its_coverage_unchanged_by_the_model_error(tmp_path):
    rc, d, text = _validate(str(CSTR), "--out", str(tmp_path / "out"))
    assert rc == 0 and d["n_rep"] == 2                          # the size study is there as before
    me = d["model_error"]
    assert me["variant"] == "arrhenius" and me["error"] is None
    assert me["kind"] == "none" and me["detected"] is False and me["sensors"] == ["C_A", "C_B", "C_C"]
    assert [s["split"] for s in me["splits"]] == ["random 1", "random 2", "random 3", "cool vs hot"]
    n = sum(s["n_values"] for s in me["splits"])
    assert me["n_values"] == n and me["coverage_with_error"] == me["coverage_plain"]
    assert me["coverage_plain"] == pytest.approx(sum(s["coverage_plain"] * s["n_values"] for s in me["splits"]) / n)
    assert all(s["widening"] == 1.0 for s in me["splits"])
    block = text.rstrip().split("\n\n")[-1]
    assert block.startswith("Held-out coverage of arrhenius's 95 % new-reading bands on the study's data")
    assert f"pooled: {100 * me['coverage_plain']:.1f} % without the model error" in block
    assert "  cool vs hot: " in block and block.count("\n") == 2 + len(me["splits"])
    assert block.split("\n")[1] == "  " + me["noise"]                  # which sigma the bands take: cstr's as given
    assert me["noise"].startswith("The model-error bands take the sigma given in [[sensors]] (C_A 0.004 mol/L")


def test_a_rejected_variant_gets_its_coverage_with_the_model_error(tmp_path):
    """The press's M1 ([validate] variant: the first listed): its error is found and widens the bands."""
    rc, d, text = _validate(str(PRESS), "--out", str(tmp_path / "out"))
    me = d["model_error"]
    assert rc == 0 and me["variant"] == "M1" and me["detected"] is True and me["kind"] != "none"
    assert me["sensors"] == ["F_x", "B0_y"] and len(me["splits"]) == 4         # the tests' sensors and splits
    assert me["coverage_with_error"] > me["coverage_plain"]
    assert all(s["widening"] > 1.0 for s in me["splits"])
    assert "model error DETECTED" in text and f"with it ({me['kind']})" in text
    assert me["noise"].startswith("The model-error bands take sigma_rep") and "  " + me["noise"] in text


def test_the_flag_and_the_config_key_skip_it(tmp_path):
    rc, d, text = _validate(str(CSTR), "--out", str(tmp_path / "flag"), "--no-model-error")
    assert rc == 0 and "model_error" not in d and "Held-out coverage" not in text
    rc, d, text = _validate(str(_own_cstr(tmp_path, "model_error = false")), "--out", str(tmp_path / "key"))
    assert rc == 0 and "model_error" not in d and "Held-out coverage" not in text


def test_a_bad_config_value_is_one_line_naming_file_line_and_key(tmp_path, capsys):
    cfg = _own_cstr(tmp_path, 'model_error = "yes"')
    line = cfg.read_text().splitlines().index('model_error = "yes"') + 1
    out = tmp_path / "out"
    one_line_error(capsys, ["validate", str(cfg), "--out", str(out)], f"cstr.toml:{line}:", "model_error:",
                   "expected true or false")
    assert not out.exists() or not any(p.name.startswith("validate") for p in out.iterdir())


def test_a_failed_model_error_is_a_line_not_a_failed_command(tmp_path, monkeypatch):
    from identification.errors import IdentificationError
    import mudoe.model_error_runs as runs

    def fails(*args, **kwargs):
        raise IdentificationError("the error model's fit did not converge")
    monkeypatch.setattr(runs, "model_error", fails)
    rc, d, text = _validate(str(CSTR), "--out", str(tmp_path / "out"))
    assert rc == 0 and d["model_error"] == {"variant": "arrhenius", "error": "the error model's fit did not converge"}
    assert text.rstrip().endswith("Held-out coverage with the model error of arrhenius: not computed: the error "
                                  "model's fit did not converge")
