"""``mudoe quantify``: the model error of every variant of a static study (issue 29, item 4)."""
import json
from pathlib import Path

import pytest

from mudoe.cli import main
from mudoe.outdir import MARKER

REPO = Path(__file__).resolve().parents[2]
PRESS = REPO / "configs" / "press.toml"


@pytest.fixture(scope="module")
def press_quantify(tmp_path_factory):
    """``mudoe quantify configs/press.toml --json`` once: (exit code, stdout, out folder)."""
    import io
    from contextlib import redirect_stdout
    out = tmp_path_factory.mktemp("quantify") / "out"
    buf = io.StringIO()
    with redirect_stdout(buf):
        rc = main(["quantify", str(PRESS), "--out", str(out), "--quiet", "--json"])
    return rc, buf.getvalue(), out


def _one_line_error(capsys, argv, *words):
    rc = main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def test_writes_both_files_with_the_keys(press_quantify):
    rc, stdout, out = press_quantify
    assert rc == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, "quantify.json", "quantify.txt"])
    d = json.loads((out / "quantify.json").read_text())
    assert json.loads(stdout) == d                     # --json prints what the file holds
    assert set(d) == {"sensors", "design_how", "variants", "errors"}
    assert set(d["variants"]) == {"M1", "M2", "M3"} and d["errors"] == {}
    assert d["sensors"] == ["F_x", "B0_y"]             # the study's E-optimal design, as in the tests
    for v, r in d["variants"].items():
        assert {"detected", "kind", "test", "heldout", "discrepancies", "embedded_parameters", "pooled_coverage",
                "size_file_units", "p", "conf_int"} <= set(r)
        assert len(r["heldout"]) == 4                  # the paper's four split scenarios
        assert [s["sensor"] for s in r["size_file_units"]] == (["F_x", "B0_y"] if r["kind"] == "discrepancy" else [])
        assert {s["unit"] for s in r["size_file_units"]} <= {"um"}      # the files' unit, not the model's mm
        assert [e["name"] for e in r["embedded_parameters"]] == ["k5", "k7"]
    m1 = d["variants"]["M1"]
    # bench/RESULTS.md "Issue 29 (first slice)": M1 is detected, 76.8 % plain and 89.3 % discrepancy coverage
    assert m1["detected"] is True and m1["kind"] == "discrepancy"
    assert m1["pooled_coverage"]["plain"] == pytest.approx(129 / 168)
    assert m1["pooled_coverage"]["with_error"] == pytest.approx(150 / 168)
    f_x = m1["size_file_units"][0]
    assert 5.0 < f_x["amplitude"] < 10.0               # about 7 um, not 0.007 (mm)


def test_text_file_has_the_summary_per_variant(press_quantify):
    _, _, out = press_quantify
    text = (out / "quantify.txt").read_text()
    for v in ("M1", "M2", "M3"):
        assert f"{v}: model error DETECTED" in text
        assert f"---- {v} in full ----\nModel error of " in text     # the full ModelErrorResult.summary()
    assert "without the model error" in text and " um " in text


def test_dynamic_study_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    line = _one_line_error(capsys, ["quantify", str(REPO / "configs" / "oscillator.toml"), "--out", str(out),
                                    "--quiet"], "static models only")
    assert line.startswith("mudoe quantify: error:")
    assert not (out / "quantify.json").exists() and not (out / "quantify.txt").exists()


def test_unknown_config_is_bad_input(tmp_path, capsys):
    out = tmp_path / "out"
    _one_line_error(capsys, ["quantify", str(tmp_path / "none.toml"), "--out", str(out)], "config file not found")
    assert not out.exists() or not any(out.iterdir())


def test_quantify_is_listed_in_help(capsys):
    from mudoe.cli import build_parser
    assert "quantify" in build_parser().format_help()
