"""Texts and checks shared by the CLI tests of tests/mudoe (imported by name: pytest puts this folder on
sys.path for its test modules)."""
import textwrap

from mudoe.cli import main

#: a press study without data: designs planned at the parameters' start values
PLANNED_PRESS = textwrap.dedent("""\
    [model]
    name = "press"
    variants = ["M1"]

    [data]
    source = "csv"
    directory = "no_such_folder"
    displacement_unit = "um"

    [[sensors]]
    name = "D_y"
    sigma = 15.0
    [[sensors]]
    name = "F_x"
    sigma = 5.0
    [[sensors]]
    name = "B0_y"
    sigma = 4.0

    [[parameters]]
    name = "k5"
    start = 530.0
    lower = 1.0
    upper = 1.0e5
    [[parameters]]
    name = "k7"
    start = 470.0
    lower = 1.0
    upper = 1.0e5

    [oed]
    planned = true
    criterion = "D"
    kind = "gauss_newton"
    candidates_range = [0.0, 1600.0, 9]
    """)


def one_line_error(capsys, argv, *words):
    """Run the CLI with ``argv``: exit code 2, one line on stderr holding every word, no traceback."""
    rc = main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def planned_design_pages(text: str, path) -> tuple:
    """(plan, figures): the design that ``mudoe oed`` plans before data for the config ``text`` (read as if from
    ``path``) and its design pages (reports.design_pages), drawn from a study record without data."""
    from mudoe.config import parse_config
    from mudoe.plans import plan_without_data
    from mudoe.study_models import build_models
    from reports.design_pages import design_pages
    from tests.reports.record_stub import stub_record
    cfg = parse_config(text, str(path))
    plan = plan_without_data(cfg)
    return plan, design_pages(stub_record({k: b.model for k, b in build_models(cfg).items()}, plan=plan))
