"""Shared fixtures of the mudoe CLI tests: a small synthetic press campaign written as CSV."""
from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

SIGMA_UM = (15.0, 5.0, 4.0)


def config_text(directory, layout="paper", variants='["M1"]', extra="", sensors=None, data_extra=""):
    """A small M1-only study config (0-based series, paper scenarios) as TOML text."""
    if sensors is None:
        sensors = "".join(f'\n[[sensors]]\nname = "{s}"\nsigma = {v}\n'
                          for s, v in zip(("D_y", "F_x", "B0_y"), SIGMA_UM))
    return textwrap.dedent(f"""\
        [model]
        name = "press"
        variants = {variants}

        [data]
        source = "csv"
        layout = "{layout}"
        directory = "{directory}"
        displacement_unit = "um"
        force_unit = "N"
        {data_extra}
        """) + sensors + textwrap.dedent("""
        [[parameters]]
        name = "k5"
        start = 500.0
        lower = 1.0
        upper = 1.0e5

        [[parameters]]
        name = "k7"
        start = 500.0
        lower = 1.0
        upper = 1.0e5

        [splits]
        scenarios = ["paper"]

        [detect]
        sensors = "all"

        [oed]
        variant = "M1"
        """) + extra


@pytest.fixture(scope="session")
def synthetic():
    """(q_set N, z mm (3 series, 29 loads, 3 sensors), sensors) from the press model M1 at (530, 470) N/mm."""
    from models.press import PRESS_SENSORS, Q_PAPER, press_model
    m = press_model()
    q = np.asarray(Q_PAPER)
    h = m.simulate([530.0, 470.0], q[:, None])
    rng = np.random.default_rng(7)
    z = h[None] + 1e-3 * np.asarray(SIGMA_UM) * rng.standard_normal((3,) + h.shape)
    return q, z, tuple(PRESS_SENSORS)


@pytest.fixture()
def campaign_dirs(tmp_path, synthetic):
    """Both layouts of the synthetic campaign plus a config for each; returns dict of paths."""
    from mudoe.data_io import write_paper_layout, write_tidy_layout
    q, z, sensors = synthetic
    paper = tmp_path / "paper"
    tidy = tmp_path / "tidy"
    write_paper_layout(paper, q, z, sensors, "um", "N")
    write_tidy_layout(tidy / "campaign_long.csv", q, z, sensors, "um", "N")
    cp = tmp_path / "paper.toml"
    cp.write_text(config_text(paper, "paper"))
    ct = tmp_path / "tidy.toml"
    ct.write_text(config_text(tidy, "tidy"))
    return dict(root=tmp_path, paper=paper, tidy=tidy, paper_cfg=cp, tidy_cfg=ct)


REPO = Path(__file__).resolve().parents[2]


def write_cstr_config(tmp_path, layout="tidy") -> Path:
    """configs/cstr.toml with its data folder in ``tmp_path/data``, a small report and few runs."""
    text = (REPO / "configs" / "cstr.toml").read_text()
    text = text.replace('directory = "../data/cstr"', 'directory = "data"')
    text = text.replace('layout = "tidy"', f'layout = "{layout}"')
    text = text.replace("[report]\n", "[report]\ndpi = 30\n")
    path = tmp_path / "cstr.toml"
    path.write_text(text)
    return path


@pytest.fixture()
def cstr_config():
    """The factory :func:`write_cstr_config` (the CSTR study of configs/cstr.toml in a temporary folder)."""
    return write_cstr_config
