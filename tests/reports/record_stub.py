"""A typed study record for report tests that need no study: the models, and whatever results a test sets."""
from oed.study_record import ConfigRecord, DataSource, StudyRecord, StudySetup


def stub_record(models: dict, pages: str = "fits", **results) -> StudyRecord:
    """An :class:`oed.study_record.StudyRecord` of ``models`` ({variant: Model}) without data, with ``results``
    (StudyRecord fields, e.g. ``plan=...``)."""
    first = next(iter(models.values()), None)
    setup = StudySetup(config=ConfigRecord(path="", text="", values={}, title="test", dpi=40, uncertainty="none"),
                       source=DataSource(source="none", files=(), sha256="", n_M=0, n_q=0), campaign=None,
                       sensors=tuple(first.sensors) if first is not None else (), sigma=None, sigma_table=(),
                       normality=None, models=dict(models), data={}, p0=None, splits=(), pages=pages)
    return StudyRecord(study=setup, **results)
