r"""The one strategy a study kind implements: what really differs between a static and a time-series study.

Every command runs the same path (:mod:`mudoe.study`, :mod:`mudoe.cli`): build the models, choose
the kind once from them (:func:`mudoe.kind.study_kind`), then ask the kind for what differs

* the data: its reader and writer (wide CSV of set points, or the long time-series CSV) and the
  config section that declares them (none, or ``[dynamic]``) -- :meth:`StudyKind.prepare`,
  :meth:`StudyKind.simulate`;
* how the models are started (the [[parameters]] starts, per variant) and bounded -- ``prepare``;
* the design run (sensors at the set points, or sampling times) -- :meth:`StudyKind.run_oed`,
  :meth:`StudyKind.oed_files`, :meth:`StudyKind.plan_without_data`;
* what the report pages draw beyond the fits (prediction bands, the diagnostic split family and
  the model error; or trajectories with their bands and the mesh of each fit) --
  :meth:`StudyKind.diagnose`, :meth:`StudyKind.bands`, :meth:`StudyKind.report_runs`,
  :attr:`StudyKind.report_pages`;
* the Monte Carlo size study's problem (the model itself, or its collocation at the estimate) --
  :meth:`StudyKind.validation_problem`;
* the template of ``mudoe init`` -- :meth:`StudyKind.template_text`.

The fits, the detection, the profile intervals and the outputs are the same for every kind.  A
third kind (e.g. a PDE the user discretises) is one more subclass and one line in
:func:`mudoe.kind.kind_of`.
"""
from __future__ import annotations

__all__ = ["StudyKind", "Simulation"]


class Simulation:
    """A simulated campaign of a kind, ready to be written (``mudoe simulate``)."""

    def write(self, cfg, out) -> tuple:
        """(paths written into the folder ``out``, the record of simulate.json)."""
        raise NotImplementedError


class StudyKind:
    """What a kind of study does its own way (see the module docstring); the kinds hold no state.

    Attributes
    ----------
    name : str             "static" or "time series" (for messages)
    report_pages : str     what the report draws beyond the fits: "fits" (bands, diagnosis, model error)
                           or "trajectories" (trajectories with bands, the mesh of each fit)
    model_error_refusal : str   why ``mudoe quantify`` cannot run on this kind ("" when it can)
    input_rows : str       what the report calls the input rows ("set points", "experiments")
    normality_over : str   which readings the normality gate pools (words for the report)
    """

    name = ""
    report_pages = ""
    model_error_refusal = ""
    input_rows = "set points"
    normality_over = "all set points"

    def refusal(self, command: str) -> str:
        """Why this kind cannot run the CLI ``command`` ("" when it can): ``quantify`` needs a model error."""
        return self.model_error_refusal if command == "quantify" else ""

    def prepare(self, cfg, built: dict, progress):
        """The :class:`mudoe.study_base.Study` of the built variants ({variant: VariantModel}): data, sigma,
        splits, start values."""
        raise NotImplementedError

    def simulate(self, cfg, built: dict, seed: int | None) -> Simulation:
        """A campaign simulated from the study's own model ([simulate]), in the kind's data format."""
        raise NotImplementedError

    def plan_without_data(self, cfg, built: dict, progress):
        """``[oed] planned = true``: the design at the [[parameters]] starts, no data read."""
        raise NotImplementedError

    def run_oed(self, study, results, progress):
        """``results`` with the design at the estimate of the [oed] variant (oed, oed_table, design_sensors)."""
        raise NotImplementedError

    def oed_files(self, study, results, progress) -> tuple:
        """``mudoe oed``: (text of oed.txt, the object of oed.json)."""
        raise NotImplementedError

    def plan_at_estimate(self, study, results, progress):
        """The design of ``[oed] mode`` inputs / both / discrimination at the estimate for the report (a record of
        :mod:`oed.plan_records`), after :meth:`run_oed`; None when there is none."""
        raise NotImplementedError

    def diagnose(self, study, results, progress):
        """``results`` with the diagnostic split family (unchanged where the kind has none)."""
        raise NotImplementedError

    def bands(self, study, results, level: float):
        """``results`` with the prediction bands of every fit (unchanged where the trajectories carry them)."""
        raise NotImplementedError

    def report_runs(self, study, results, progress):
        """``results`` with what the report draws beyond the fits and the tests (see :attr:`report_pages`)."""
        raise NotImplementedError

    def validation_problem(self, study, results, est, used) -> tuple:
        """(model, splits, weights) of the Monte Carlo size study of ``est`` with the instruments ``used``."""
        raise NotImplementedError

    def template_text(self, model, name: str) -> str:
        """The commented config template of ``mudoe init --model name`` for ``model``."""
        raise NotImplementedError
