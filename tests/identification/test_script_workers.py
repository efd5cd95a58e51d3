"""Replications started from a plain script (issue 30): a script without `if __name__ == "__main__":`
or read from stdin runs serially with one WorkersWarning saying why (spawned workers would run the
script again or cannot import it), a guarded script uses the local processes; a task that cannot be
sent runs serially with the warning too.  Never a BrokenProcessPool."""
import json
import subprocess
import sys
import textwrap
import threading
import warnings
from pathlib import Path

import pytest

from identification import cluster

REPO = Path(__file__).resolve().parents[2]

BODY = textwrap.dedent("""\
    import numpy as np
    from models import Model
    from identification.studies.montecarlo import MonteCarloSettings, validate
    from identification.studies.splits import Split

    m = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0])
    """)
CALL = ('res = validate(m, [Split("half", [0, 1], [2, 3])], [1.0, 1.0], p=[1.0, 2.0], '
        'inputs=np.arange(4.0)[:, None], sigma=[0.1], '
        'settings=MonteCarloSettings(n_rep=4, seed=1, workers=2, progress=False, jit=False))\n'
        'print("BACKEND", res.backend)\n')


def _python(tmp_path, script: str, stdin: bool):
    env = {"PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    if stdin:
        return subprocess.run([sys.executable, "-"], input=script, capture_output=True, text=True, env=env,
                              cwd=tmp_path, timeout=300)
    path = tmp_path / "study.py"
    path.write_text(script)
    return subprocess.run([sys.executable, str(path)], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=300)


@pytest.mark.parametrize("stdin, why", [(False, "study.py starts it from its top level (line 7) without"),
                                        (True, "the script was read from standard input")])
def test_unguarded_script_and_stdin_run_serially_with_one_warning(tmp_path, stdin, why):
    run = _python(tmp_path, BODY + CALL, stdin)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "BACKEND serial (this process)" in run.stdout
    assert run.stderr.count("WorkersWarning") == 1 and why in run.stderr
    assert "BrokenProcessPool" not in run.stderr and "bootstrapping" not in run.stderr


def test_guarded_script_uses_the_local_processes(tmp_path):
    script = BODY + 'if __name__ == "__main__":\n' + textwrap.indent(CALL, "    ")
    run = _python(tmp_path, script, stdin=False)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "BACKEND local processes (2 workers" in run.stdout and "WorkersWarning" not in run.stderr


def test_a_task_that_cannot_be_sent_runs_here_with_the_warning():
    got = []
    with pytest.warns(cluster.WorkersWarning, match="cannot be sent to worker processes"):
        backend = cluster.execute(lambda task, chunk: [len(chunk)], threading.Lock(), lambda n: [[1, 2], [3]],
                                  got.extend, workers=2, install=print)
    assert backend.kind == "serial" and got == [2, 1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cluster.main_rerun_hazard() == ""        # pytest's own __main__ is not re-run by spawned workers


NOTEBOOK_MODEL = textwrap.dedent("""\
    import casadi as ca
    import numpy as np
    from identification import Measurements, identify
    from models import Model, Parameter

    T = np.linspace(0.0, 10.0, 41)
    model = Model.explicit(params=[Parameter("a", -10.0, 10.0), Parameter("w", 0.1, 5.0)], inputs=["t"],
                           sensors=["y"], h=lambda p, q: p[0] * ca.sin(p[1] * q[0]), name="sinusoid")
    z = (2.0 * np.sin(1.7 * T))[None, :, None] + 0.1 * np.random.default_rng(1).standard_normal((1, T.size, 1))
    data = Measurements(T, z, [0.1])
    """)
NOTEBOOK_CALL = textwrap.dedent("""\
    import json, sys, warnings
    from identification import cluster
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est = identify(model, data, [1.0, 0.5], starts=4, workers=2)
    print(json.dumps({"exe": sys.executable, "main_file": getattr(sys.modules["__main__"], "__file__", None),
                      "hazard": cluster.main_rerun_hazard(), "backend": est.diagnostics.starts.backend,
                      "p": [v.hex() for v in est.p], "cov": [v.hex() for v in est.cov.ravel()],
                      "objective": est.objective.hex(), "starts_p": [v.hex() for v in est.diagnostics.starts.p.ravel()],
                      "warnings": [f"{w.category.__name__}: {w.message}" for w in caught]}))
    """)


def test_a_notebook_kernel_ships_its_model_to_local_processes(tmp_path):
    """A model defined in a notebook cell (the kernel's ``__main__`` has no file) is shipped by value to the local
    processes of identify(..., starts=4, workers=2), run by a real ipykernel of this interpreter through nbclient:
    the cell finishes on 2 local processes without a warning and gives the serial estimate of this process."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import KernelManager
    spec = tmp_path / "kernels" / "mudoe-test"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"], "language": "python",
        "display_name": "mudoe test", "env": {"PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1"}}))
    km = KernelManager(kernel_name="mudoe-test", kernel_spec_manager=KernelSpecManager(kernel_dirs=[str(spec.parent)]))
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(NOTEBOOK_MODEL),
                                         nbformat.v4.new_code_cell(NOTEBOOK_CALL)])
    nbclient.NotebookClient(nb, km=km, timeout=300, startup_timeout=120, resources={"metadata": {"path": str(tmp_path)}}
                            ).execute()
    text = "".join(o.get("text", "") for o in nb.cells[1].outputs if o.get("name") == "stdout")
    out = json.loads([line for line in text.splitlines() if line.startswith('{"exe"')][-1])
    assert out["exe"] == sys.executable and out["main_file"] is None and out["hazard"] == ""
    assert out["backend"] == "2 local processes" and out["warnings"] == []
    from identification import identify
    env = {}
    exec(NOTEBOOK_MODEL, env)
    serial = identify(env["model"], env["data"], [1.0, 0.5], starts=4)
    assert serial.diagnostics.starts.backend == "serial"
    assert out["p"] == [v.hex() for v in serial.p] and out["cov"] == [v.hex() for v in serial.cov.ravel()]
    assert out["objective"] == serial.objective.hex()
    assert out["starts_p"] == [v.hex() for v in serial.diagnostics.starts.p.ravel()]
