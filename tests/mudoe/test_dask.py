"""``mudoe validate --scheduler ADDRESS`` and ``[validate] scheduler``: the size study on a Dask cluster.

The cluster is a ``distributed.LocalCluster`` started by the test (2 in-process workers, one
thread each); its numbers must equal the serial backend's (replication r draws from
SeedSequence(seed).spawn(n_rep)[r] wherever it runs).
"""
from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest

from identification.cluster import SchedulerError, connect
from identification.studies.montecarlo import MonteCarloSettings
from mudoe.cli import main
from mudoe.config import ConfigError, parse_config

distributed = pytest.importorskip("distributed", reason="dask[distributed] is in the test extras (make setup)")


@pytest.fixture(autouse=True)
def no_jit(monkeypatch):
    """The size studies here run without the C compilation of the model (MonteCarloSettings.jit: same
    numbers, a one-off 1-10 s per process that these tests do not check)."""
    from mudoe.config import ValidateConfig
    settings = ValidateConfig.settings
    monkeypatch.setattr(ValidateConfig, "settings",
                        lambda self, *a, **k: dataclasses.replace(settings(self, *a, **k), jit=False))


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cl:
        yield cl


def _lines(capsys):
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    return cap.out, [ln for ln in cap.err.splitlines() if ln.strip()]


def test_same_numbers_serial_and_dask_from_the_study(campaign_dirs, cluster):
    from mudoe.config import load_config
    from mudoe.study import StudyResults, prepare, run_identify, run_validate
    cfg = load_config(campaign_dirs["paper_cfg"])
    cfg = dataclasses.replace(cfg, validate=dataclasses.replace(cfg.validate, n_runs=3, seed=5))
    study = prepare(cfg)
    results = run_identify(study, StudyResults(study))
    serial = run_validate(study, results, workers=1).validation
    dask = run_validate(study, results, scheduler=cluster.scheduler_address).validation
    assert serial.backend.startswith("serial") and dask.backend.startswith("dask (")
    assert "2 workers" in dask.backend
    for name in ("alpha_paper", "alpha_two_sample", "alpha_lr", "covered"):
        a, b = getattr(serial, name), getattr(dask, name)
        assert np.isfinite(a).any(), name
        np.testing.assert_array_equal(a, b, err_msg=name)


def test_cli_flag_and_config_key_reach_the_cluster(campaign_dirs, cluster, capsys, tmp_path):
    out = tmp_path / "out"
    addr = cluster.scheduler_address
    rc = main(["validate", str(campaign_dirs["paper_cfg"]), "--runs", "1", "--scheduler", addr, "--out", str(out),
               "--no-model-error"])
    text, err = _lines(capsys)
    assert rc == 0, err
    assert f"dask ({addr}, 2 workers)" in (out / "validate.txt").read_text()
    assert any(f"on the Dask scheduler {addr}" in ln for ln in err)
    cfg = tmp_path / "key.toml"
    cfg.write_text(campaign_dirs["paper_cfg"].read_text() + f'\n[validate]\nn_runs = 1\nscheduler = "{addr}"\n')
    out2 = tmp_path / "out2"
    rc = main(["validate", str(cfg), "--out", str(out2), "--quiet", "--no-model-error"])
    _lines(capsys)
    assert rc == 0 and f"dask ({addr}, 2 workers)" in (out2 / "validate.txt").read_text()


def test_unreachable_scheduler_is_one_line_and_exit_2(campaign_dirs, capsys, tmp_path):
    import dask
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        rc = main(["validate", str(campaign_dirs["paper_cfg"]), "--runs", "2", "--scheduler", "tcp://127.0.0.1:9",
                   "--out", str(tmp_path / "o"), "--quiet"])
    _, err = _lines(capsys)
    assert rc == 2
    assert len(err) == 1 and "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in err[0], err
    assert "dask scheduler" in err[0]


def test_dask_not_installed_is_one_line_and_exit_2(campaign_dirs, capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)          # import distributed -> ImportError
    rc = main(["validate", str(campaign_dirs["paper_cfg"]), "--runs", "2", "--scheduler", "tcp://127.0.0.1:9",
               "--out", str(tmp_path / "o"), "--quiet"])
    _, err = _lines(capsys)
    assert rc == 2 and len(err) == 1 and "Dask is not installed" in err[0] and "dask[distributed]" in err[0], err


def test_bad_scheduler_values_name_the_key_or_option(campaign_dirs, capsys, tmp_path):
    with pytest.raises(ConfigError, match=r"scheduler: expected a Dask scheduler address"):
        parse_config('[validate]\nscheduler = ""\n', "s.toml")
    with pytest.raises(ConfigError, match=r"s.toml:2:.*scheduler"):
        parse_config('[validate]\nscheduler = 8786\n', "s.toml")
    assert parse_config('[validate]\nscheduler = "tcp://h:8786"\n', "s.toml").validate.settings(0.05).scheduler \
        == "tcp://h:8786"
    assert parse_config("", "s.toml").validate.scheduler is None
    with pytest.raises(ValueError, match="scheduler: expected"):
        MonteCarloSettings(scheduler=3)
    rc = main(["validate", str(campaign_dirs["paper_cfg"]), "--scheduler", " ", "--out", str(tmp_path / "o"),
               "--quiet"])
    _, err = _lines(capsys)
    assert rc == 2 and len(err) == 1 and "--scheduler" in err[0]


def test_a_scheduler_without_workers_is_an_error():
    with distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cl:
        with pytest.raises(SchedulerError, match="no Dask worker joined"):
            with connect(cl.scheduler_address, worker_wait=0.5):
                pass
