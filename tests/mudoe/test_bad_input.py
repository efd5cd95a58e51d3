"""The bad-input sweep of issue 20, one test per class of fault: every case ends in one clear line
(exit 2, naming the file and line or the argument), before any work, with nothing written."""
import json
import threading
from pathlib import Path

import numpy as np
import pytest

from mudoe.cli import main

REPO = Path(__file__).resolve().parents[2]


def _conftest():
    import importlib.util
    spec = importlib.util.spec_from_file_location("mudoe_tests_conftest", Path(__file__).with_name("conftest.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


config_text = _conftest().config_text
CSTR = (REPO / "configs" / "cstr.toml").read_text().replace('directory = "../data/cstr"',
                                                              f'directory = "{REPO / "data" / "cstr"}"')


def _one_line(capsys, argv, code=2):
    rc = main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == code, err
    assert "Traceback" not in err and len(lines) == 1, err
    return lines[0]


def _line_of(text: str, needle: str) -> int:
    return next(i + 1 for i, ln in enumerate(text.splitlines()) if ln.strip().startswith(needle))


@pytest.mark.parametrize("command, edit, key", [
    ("simulate", ("n_inputs = 13", "n_inputs = 1000000000"), "[simulate] n_inputs"),
    ("simulate", ("n_series = 4", "n_series = 1000000000"), "[simulate] n_series"),
    ("identify", ("n = 3\n", "n = 100000000\n"), "[splits.random] n"),
    ("validate", ("n_runs = 20", "n_runs = 1000000000"), "[validate] n_runs"),
    ("oed", ("n_sensors = 3 ", "mode = \"inputs\"\nn_points = 3\ncandidates_range = [20.0, 80.0, 1e11]\n#"),
     "[oed] candidates_range"),
    ("report", ("title = ", "dpi = 100000\ntitle = "), "[report] dpi"),
])
def test_absurd_sizes_are_refused_before_any_work(capsys, tmp_path, monkeypatch, command, edit, key):
    """Sizes: a lower bound of memory / time from the config alone, refused with file, line and key
    (a machine of 16 GB, whatever this one has), in well under a second, nothing written."""
    monkeypatch.setattr("mudoe.limits.memory_budget", lambda: 16e9)
    text = CSTR.replace(*edit)
    cfg = tmp_path / "s.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    line = _one_line(capsys, [command, str(cfg), "--out", str(out), "--quiet"])
    name = key.split()[1]
    assert f"s.toml:{_line_of(text, name + ' =')}: {key}:" in line, line
    assert "would need at least" in line and "GB" in line, line
    assert not out.exists()


def test_validate_runs_option_is_sized_too(capsys, tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text(CSTR)
    line = _one_line(capsys, ["validate", str(cfg), "--runs", str(10 ** 12), "--out", str(tmp_path / "o"), "--quiet"])
    assert line.startswith("mudoe validate: error: --runs:") and "days" in line, line


def _paper_rows(path: Path) -> list:
    return path.read_text().splitlines()


@pytest.mark.parametrize("fault, where", [
    ("short row", "ragged row: 6 fields but the header has 4"),
    ("long row", "ragged row: 5 fields but the header has 4"),
    ("text", "column 'series_2': 'abc' is not a number"),
    ("infinite", "column 'series_2': infinite value"),
])
def test_streaming_reader_names_line_and_column_in_any_block(tmp_path, monkeypatch, fault, where):
    """The CSV reader works block by block (here blocks of ~200 bytes): values across block ends,
    blank and CRLF lines are read exactly as one piece; a fault in a late block names its line."""
    from mudoe import csv_stream
    from mudoe.data_io import DataFileError, read_paper_layout
    rng = np.random.default_rng(1)
    q, z = np.arange(60.0), rng.standard_normal((3, 60))
    lines = ["force_N,series_1,series_2,series_3"] + [",".join(repr(float(v)) for v in (q[j], *z[:, j]))
                                                     for j in range(60)]
    lines.insert(10, "")                       # a blank line, and CRLF line ends below
    f = tmp_path / "measurements_D_y.csv"
    f.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    monkeypatch.setattr(csv_stream, "BLOCK_BYTES", 200)
    c = read_paper_layout({"D_y": f}, "mm", "N")
    assert np.array_equal(c.q_set, q) and np.array_equal(c.z[:, :, 0], z)
    bad = list(lines)
    row = bad[50].split(",")
    row = {"short row": row[:3], "long row": row + ["1.0"], "text": row[:2] + ["abc"] + row[3:],
           "infinite": row[:2] + ["-inf"] + row[3:]}[fault]
    if fault == "short row":                   # a row of 6 fields has more separators than a short one
        row = row + ["1", "2", "3"]
    bad[50] = ",".join(row)
    f.write_text("\n".join(bad) + "\n")
    with pytest.raises(DataFileError) as e:
        read_paper_layout({"D_y": f}, "mm", "N")
    assert f"measurements_D_y.csv:51: " in str(e.value) and where in str(e.value), str(e.value)


def test_tidy_reader_blocks_agree_and_duplicates_name_the_line(tmp_path, monkeypatch, synthetic):
    from mudoe import csv_stream
    from mudoe.data_io import DataFileError, read_tidy_layout, write_tidy_layout
    q, z, sensors = synthetic
    f = write_tidy_layout(tmp_path / "t.csv", q, z, sensors, "um", "N")
    whole = read_tidy_layout(f, "um", "N", sensors=sensors)
    monkeypatch.setattr(csv_stream, "BLOCK_BYTES", 300)
    parts = read_tidy_layout(f, "um", "N", sensors=sensors)
    assert np.array_equal(whole.z, parts.z) and np.array_equal(whole.q_set, parts.q_set)
    assert whole.series == parts.series
    text = f.read_text()
    quoted = tmp_path / "q.csv"                # quoted labels and CRLF line ends: the csv-module count
    quoted.write_bytes("\r\n".join(",".join(f'"{c}"' if not c[:1].isdigit() and c[:1] != "-" else c
                                              for c in ln.split(",")) for ln in text.splitlines()).encode())
    q_parts = read_tidy_layout(quoted, "um", "N", sensors=sensors)
    assert np.array_equal(whole.z, q_parts.z) and whole.series == q_parts.series
    lines = f.read_text().splitlines()
    lines.append(lines[100])                   # the same reading twice
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError, match=rf"t.csv:{len(lines)}: duplicate row for series"):
        read_tidy_layout(f, "um", "N", sensors=sensors)


def _cross(campaign_dirs, extra="", data_extra="", sensors=None, variants='["M1"]', edit=None):
    text = config_text(campaign_dirs["paper"], "paper", variants=variants, extra=extra, data_extra=data_extra,
                       sensors=sensors)
    if edit:
        text = text.replace(*edit)
    cfg = campaign_dirs["root"] / "x.toml"
    cfg.write_text(text)
    return cfg, text


@pytest.mark.parametrize("case, needle, words", [
    ("n_sensors", "n_sensors", ("[oed] n_sensors: n_sensors = 7 but the model has 3 sensors",)),
    ("detect empty", "sensors = []", ("[detect] sensors:", "empty")),
    ("series twice", "series = [0, 0]", ("[data] series:", "twice")),
    ("split index 99", "cal_inputs", ("[[splits.custom]] cal_inputs:", "index 99 is out of range", "29 inputs")),
    ("lower == upper", "upper = 500.0", ("[parameters] upper:", "lower = upper")),
])
def test_cross_key_checks_before_the_fits_name_file_and_line(capsys, campaign_dirs, case, needle, words):
    extra = {"n_sensors": "n_sensors = 7\n",
             "split index 99": "[[splits.custom]]\nname = \"c\"\ncal_inputs = [1, 99]\nval_inputs = [3, 4]\n"}
    kw = dict(extra=extra.get(case, ""))
    if case == "detect empty":
        kw["edit"] = ('sensors = "all"', "sensors = []")
    if case == "series twice":
        kw["data_extra"] = "series = [0, 0]"
    if case == "lower == upper":
        kw["edit"] = ("lower = 1.0\nupper = 1.0e5\n\n[[parameters]]\nname = \"k7\"",
                      "lower = 500.0\nupper = 500.0\n\n[[parameters]]\nname = \"k7\"")
    cfg, text = _cross(campaign_dirs, **kw)
    out = campaign_dirs["root"] / "out"
    line = _one_line(capsys, ["identify", str(cfg), "--out", str(out)])
    assert f"x.toml:{_line_of(text, needle)}:" in line, line
    for w in words:
        assert w in line, line
    assert not out.exists()


def test_sensor_without_any_reading_names_its_file(capsys, campaign_dirs):
    f = campaign_dirs["paper"] / "measurements_F_x.csv"
    rows = f.read_text().splitlines()
    f.write_text("\n".join([rows[0]] + [r.split(",")[0] + ",NaN,,NaN" for r in rows[1:]]) + "\n")
    line = _one_line(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--out", str(campaign_dirs["root"] / "o")])
    assert "measurements_F_x.csv: sensor 'F_x' has no reading" in line, line


def test_silently_accepted_inputs_are_refused(capsys, campaign_dirs):
    """Duplicate series headers, --out "", an ellipsoid at alpha = 0.95 (like conf_int)."""
    f = campaign_dirs["paper"] / "measurements_D_y.csv"
    rows = f.read_text().splitlines()
    rows[0] = rows[0].replace("series_3", "series_1")
    f.write_text("\n".join(rows) + "\n")
    line = _one_line(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--out", str(campaign_dirs["root"] / "o")])
    assert "measurements_D_y.csv:1: wrong header: series column 'series_1' appears twice" in line, line
    line = _one_line(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--out", ""])
    assert "--out: empty" in line, line

    from identification.inference.results import Estimate
    est = Estimate.__new__(Estimate)
    for bad in (0.95, 0.5, 0.0):
        with pytest.raises(ValueError, match="alpha: must lie in"):
            est.ellipsoid(bad)
        with pytest.raises(ValueError, match="alpha: must lie in"):
            est.conf_int(bad)


def test_out_folder_is_mudoes_own(capsys, tmp_path):
    """A folder with foreign files is refused; another study's outputs are removed when a new study writes."""
    from mudoe.outdir import MARKER, begin, check_out, claim, record
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("x")
    line = _one_line(capsys, ["identify", str(REPO / "configs" / "cstr.toml"), "--out", str(foreign)])
    assert "holds files mudoe did not write (thesis.tex)" in line, line
    assert sorted(p.name for p in foreign.iterdir()) == ["thesis.tex"]

    out = tmp_path / "out"
    begin(out, str(tmp_path / "a.toml"))
    claim(out)
    for name in ("page01_title.png", "page02_data.png", "identify.json"):
        (out / name).write_text("a")
    record(out, [out / "page01_title.png", out / "page02_data.png", out / "identify.json"])
    assert check_out(str(out)) == out
    begin(out, str(tmp_path / "b.toml"))       # another study writes here: the old outputs go first
    claim(out)
    assert sorted(p.name for p in out.iterdir()) == [MARKER]
    assert json.loads((out / MARKER).read_text())["study"] == str((tmp_path / "b.toml").resolve())


def test_init_creates_its_file_exclusively(tmp_path):
    """Of concurrent writers of one path exactly one succeeds and the file is complete."""
    from models.fileio import create_text
    for trial in range(8):
        path = tmp_path / f"s{trial}.toml"
        wins, errors = [], []

        def write(k):
            try:
                create_text(path, f"writer {k}\n" * 1000)
                wins.append(k)
            except FileExistsError:
                errors.append(k)

        threads = [threading.Thread(target=write, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert len(wins) == 1 and len(errors) == 3
        assert path.read_text() == f"writer {wins[0]}\n" * 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"s{t}.toml" for t in range(8)]


def test_faults_of_factory_friction_file_and_disk_are_one_clear_line(capsys, tmp_path, monkeypatch,
                                                                      campaign_dirs):
    (tmp_path / "exitfactory.py").write_text("import sys\ndef build(variant):\n    sys.exit(7)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = tmp_path / "f.toml"
    cfg.write_text(CSTR.replace("mudoe.example_cstr:build", "exitfactory:build"))
    line = _one_line(capsys, ["identify", str(cfg), "--out", str(tmp_path / "o")])
    assert "exitfactory:build('arrhenius') called sys.exit(7)" in line, line

    (campaign_dirs["root"] / "bad.json").write_text('{"q_c_N": 3.0,\n "network": [1, 2,\n}\n')
    cfg, text = _cross(campaign_dirs, variants='["M1", "M2"]',
                       edit=('variants = ["M1", "M2"]', 'variants = ["M1", "M2"]\nfriction_file = "bad.json"'))
    line = _one_line(capsys, ["identify", str(cfg), "--out", str(campaign_dirs["root"] / "o")])
    assert f"x.toml:{_line_of(text, 'friction_file')}: [model] friction_file:" in line, line
    assert "bad.json:3: not valid JSON" in line, line

    import os
    real_fdopen = os.fdopen

    def full(fd, *a, **k):                     # every write goes to /dev/full: [Errno 28]
        os.close(fd)
        return real_fdopen(os.open("/dev/full", os.O_WRONLY), *a, **k)

    monkeypatch.setattr("models.fileio.os.fdopen", full)
    out = tmp_path / "disk"
    line = _one_line(capsys, ["init", str(out.with_suffix(".toml"))])
    assert "[Errno 28]" in line and "disk.toml" in line, line
    assert not out.with_suffix(".toml").exists()


def test_a_factory_whose_rhs_has_the_wrong_length_is_one_line_naming_it(capsys, tmp_path, monkeypatch):
    # issue 30 (bad input): the model's own error (rhs returns 1 derivative for 2 states) named with the config's
    # file and line, the factory and its variant; exit 2 before any work, nothing written
    (tmp_path / "shortrhs.py").write_text(
        "import casadi as ca\nfrom models import Model\n\n\ndef build(variant='default'):\n"
        "    return Model.ode(['k1', 'k2'], ['cA', 'cB'], [], ['cA', 'cB'], rhs=lambda x, p, u: -p[0] * x[0],\n"
        "                     x0=lambda p, u: ca.vertcat(1.0, 0.0), h=lambda x, p, u: x)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    line = _one_line(capsys, ["init", "--model", "shortrhs:build", str(tmp_path / "s.toml")])
    assert line.endswith("--model: the model factory shortrhs:build('default') cannot build its model: rhs returns 1 "
                         "derivatives but 2 states are named (cA, cB)"), line
    assert not (tmp_path / "s.toml").exists()
    cfg = tmp_path / "f.toml"
    cfg.write_text(CSTR.replace("mudoe.example_cstr:build", "shortrhs:build"))
    line = _one_line(capsys, ["identify", str(cfg), "--out", str(tmp_path / "o")])
    assert f"f.toml:{_line_of(CSTR, 'name = ')}: [model] name: the model factory shortrhs:build('arrhenius') " \
           "cannot build its model: rhs returns 1 derivatives but 2 states are named (cA, cB)" in line, line
    assert not (tmp_path / "o").exists()
