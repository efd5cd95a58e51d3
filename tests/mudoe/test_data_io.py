"""CSV import: both layouts give the same campaign and the same estimates; malformed files fail clearly."""
import numpy as np
import pytest

from mudoe.config import load_config
from mudoe.data_io import DataFileError, read_paper_layout, read_tidy_layout, write_paper_layout
from mudoe.study import StudyResults, prepare, run_identify


def test_both_layouts_give_identical_campaigns_and_estimates(campaign_dirs, synthetic):
    q, z, sensors = synthetic
    res = {}
    for layout in ("paper", "tidy"):
        study = prepare(load_config(campaign_dirs[f"{layout}_cfg"]))
        np.testing.assert_allclose(study.campaign.z, z, rtol=1e-14, atol=1e-15)   # um -> mm once
        np.testing.assert_array_equal(study.campaign.q_set, q)
        r = run_identify(study, StudyResults(study))
        res[layout] = r.estimates["M1"]
    np.testing.assert_allclose(res["paper"].p, res["tidy"].p, rtol=0, atol=1e-10)
    np.testing.assert_allclose(res["paper"].cov, res["tidy"].cov, rtol=1e-9)
    # the synthetic truth is (530, 470) N/mm: the estimate is within 4 standard errors
    assert np.all(np.abs(res["paper"].p - [530.0, 470.0]) < 4 * res["paper"].stderr)


def test_shipped_campaign_layouts_agree():
    """The shipped paper-layout files and the shipped tidy table hold the same corrected readings."""
    from models.prototype import CAMPAIGN_DIR
    files = {s: CAMPAIGN_DIR / f"measurements_{s}.csv" for s in ("D_y", "F_x", "B0_y")}
    a = read_paper_layout(files, "um", "N")
    b = read_tidy_layout(CAMPAIGN_DIR / "campaign_long.csv", "um", "N", "value", ("D_y", "F_x", "B0_y"))
    np.testing.assert_allclose(a.z, b.z, atol=1e-12)
    np.testing.assert_allclose(a.q_set, b.q_set)
    assert b.q_actual is not None and a.q_actual is None


def test_force_correction_from_raw_column_reproduces_shipped_values():
    from models.prototype import CAMPAIGN_DIR
    raw = read_tidy_layout(CAMPAIGN_DIR / "campaign_long.csv", "um", "N", "raw")
    val = read_tidy_layout(CAMPAIGN_DIR / "campaign_long.csv", "um", "N", "value")
    from mudoe.data_io import _force_correct
    corr = _force_correct(raw, "test")
    np.testing.assert_allclose(corr.z, val.z, atol=2e-7)   # files carry 4 decimals in um


def test_kN_and_m_units_are_converted(tmp_path, synthetic):
    q, z, sensors = synthetic
    write_paper_layout(tmp_path, q, z, sensors, "m", "kN")
    c = read_paper_layout({s: tmp_path / f"measurements_{s}.csv" for s in sensors}, "m", "kN")
    np.testing.assert_allclose(c.z, z, rtol=1e-13)
    np.testing.assert_allclose(c.q_set, q, rtol=1e-13)


def test_unit_in_header_is_converted_by_pint_or_refused(tmp_path, synthetic):
    """A force column in kN or lbf is converted (pint); a parsec is a length, an unknown suffix is refused."""
    q, z, sensors = synthetic
    write_paper_layout(tmp_path, q, z, sensors, "um", "kN")
    files = {s: tmp_path / f"measurements_{s}.csv" for s in sensors}
    np.testing.assert_allclose(read_paper_layout(files, "um", "N").q_set, q, rtol=1e-13)
    f = files["D_y"]
    text = f.read_text()
    f.write_text(text.replace("force_kN", "force_lbf", 1))
    c = read_paper_layout({"D_y": f}, "um", "N")
    np.testing.assert_allclose(c.q_set, q / 1e3 * 4.4482216152605, rtol=1e-13)
    f.write_text(text.replace("force_kN", "force_parsec", 1))
    with pytest.raises(DataFileError, match=r"measurements_D_y.csv:1: column 'force_parsec' is in parsec .*a unit of "
                                            r"length.* force_unit = 'N', a unit of force"):
        read_paper_layout({"D_y": f}, "um", "N")
    f.write_text(text.replace("force_kN", "force_xyz", 1))
    with pytest.raises(DataFileError, match=r"column 'force_xyz': unknown unit 'xyz'"):
        read_paper_layout({"D_y": f}, "um", "N")


def test_nan_cells_are_missing_values(tmp_path, synthetic):
    q, z, sensors = synthetic
    z = z.copy()
    z[1, 5, 0] = np.nan
    write_paper_layout(tmp_path, q, z, sensors)
    f = tmp_path / "measurements_D_y.csv"
    f.write_text(f.read_text().replace("NaN", ""))           # an empty cell is missing too
    c = read_paper_layout({s: tmp_path / f"measurements_{s}.csv" for s in sensors})
    assert np.isnan(c.z[1, 5, 0]) and np.isfinite(c.z).sum() == z.size - 1


def test_tidy_unknown_sensor_names_file_and_line(tmp_path, synthetic):
    from mudoe.data_io import write_tidy_layout
    q, z, sensors = synthetic
    p = write_tidy_layout(tmp_path / "t.csv", q, z, sensors)
    lines = p.read_text().splitlines()
    lines[4] = lines[4].replace("D_y", "G_x")
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError, match=r"t\.csv:5: unknown sensor 'G_x'"):
        read_tidy_layout(p, sensors=sensors)
