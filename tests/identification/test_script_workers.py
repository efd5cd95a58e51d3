"""Replications started from a plain script (issue 30): a script without `if __name__ == "__main__":`
or read from stdin runs serially with one WorkersWarning saying why (spawned workers would run the
script again or cannot import it), a guarded script uses the local processes; a task that cannot be
sent runs serially with the warning too.  Never a BrokenProcessPool."""
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
