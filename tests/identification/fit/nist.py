"""NIST StRD nonlinear-regression reference problems (pure test helper).

The ``.dat`` files in ``tests/data/nist/`` are the original NIST/ITL StRD files
(https://www.itl.nist.gov/div898/strd/nls/nls_main.shtml, public domain), copied
byte for byte from the ``NIST_STRD/`` directory of the lmfit 1.2.0 source
distribution on PyPI (``lmfit-1.2.0.tar.gz``, sha256
bc1bb6ea1dfea1db0489e400ca6b722f261f12a324a703b6e614877ca6ed0d38).

:func:`load` parses one file: the parameter block (Start 1, Start 2, certified
value, certified standard deviation), the certified residual sum of squares,
the number of observations and the data block, locating every block from the
line spans the file's own header announces (never a fixed offset), and checks
the counts against the header.

:data:`MODELS` holds the model function of each data set, transcribed from the
``Model:`` section of the file's header and written with CasADi operations;
``MODELS[name](b, x)`` takes the parameter vector ``b`` (entries b1..bk) and a
scalar or elementwise vector ``x`` (Nelson, the one data set with two predictors, takes
``x = (x1, x2)``).  :data:`RESPONSE` transforms the response where the model is stated for a
function of y (Nelson: ``log[y] = ...``); ``NistDataset.y`` is the transformed response, the one
the certified RSS refers to.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

DATA_DIR = Path(__file__).resolve().parents[2] / "data" / "nist"

__all__ = ["DATA_DIR", "NistDataset", "load", "available", "MODELS", "RESPONSE", "model_function", "h_of",
           "attainable_digits"]


@dataclass(frozen=True)
class NistDataset:
    name: str
    n: int                       # number of observations
    x: np.ndarray                # (n,) predictor; (n, d) when the file has d > 1 predictors (Nelson)
    y: np.ndarray                # (n,) response as the model states it (log y for Nelson)
    param_names: tuple[str, ...]
    start1: np.ndarray           # (n_p,)
    start2: np.ndarray           # (n_p,)
    certified: np.ndarray        # (n_p,) certified parameter values
    certified_stdev: np.ndarray  # (n_p,) certified standard deviations of the estimates
    certified_rss: float         # certified residual sum of squares
    certified_rsd: float         # certified residual standard deviation
    dof: int                     # degrees of freedom as printed in the file (Rat43: 9, a typo for 11)
    model_text: str              # the model line(s) of the header, for messages

    @property
    def n_p(self) -> int:
        return len(self.param_names)

    @property
    def n_x(self) -> int:
        """Number of predictors (columns of the data block after y)."""
        return 1 if self.x.ndim == 1 else self.x.shape[1]


_SPAN = r"{}\s+\(lines\s+(\d+)\s+to\s+(\d+)\)"
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][-+]?\d+)?"


def _span(text: str, label: str) -> tuple[int, int]:
    m = re.search(_SPAN.format(re.escape(label)), text)
    if m is None:
        raise ValueError(f"no '{label}' line span in the header")
    return int(m.group(1)), int(m.group(2))


def _float(tok: str) -> float:
    return float(tok.replace("D", "E").replace("d", "e"))


def _labelled(text: str, label: str, conv=_float):
    m = re.search(rf"^{re.escape(label)}:\s+({_NUM})\s*$", text, re.M)
    if m is None:
        raise ValueError(f"no '{label}' line")
    return conv(m.group(1))


def load(name: str, data_dir: Path | str = DATA_DIR) -> NistDataset:
    """Parse ``<data_dir>/<name>.dat``; raises ValueError if it is not consistent."""
    path = Path(data_dir) / f"{name}.dat"
    text = path.read_text()
    lines = text.splitlines()

    # ---- parameter block: "  b1 =   500   250   2.389E+02  2.707E+00"
    s_lo, s_hi = _span(text, "Starting Values")
    c_lo, c_hi = _span(text, "Certified Values")
    par_re = re.compile(rf"^\s*(b\d+)\s*=\s*({_NUM})\s+({_NUM})\s+({_NUM})\s+({_NUM})\s*$")
    names, s1, s2, cert, sd = [], [], [], [], []
    for ln in lines[s_lo - 1:s_hi]:
        m = par_re.match(ln)
        if m is None:
            raise ValueError(f"{name}: malformed parameter line {ln!r}")
        names.append(m.group(1))
        s1.append(_float(m.group(2)))
        s2.append(_float(m.group(3)))
        cert.append(_float(m.group(4)))
        sd.append(_float(m.group(5)))
    if names != [f"b{i + 1}" for i in range(len(names))]:
        raise ValueError(f"{name}: parameters out of order: {names}")
    m = re.search(r"(\d+)\s+Parameters", text)
    if m is None or int(m.group(1)) != len(names):
        raise ValueError(f"{name}: header announces {m and m.group(1)} parameters, block has {len(names)}")

    # ---- certified statistics (inside the Certified Values span)
    cert_text = "\n".join(lines[c_lo - 1:c_hi])
    rss = _labelled(cert_text, "Residual Sum of Squares")
    rsd = _labelled(cert_text, "Residual Standard Deviation")
    dof = _labelled(cert_text, "Degrees of Freedom", int)
    n_obs = _labelled(cert_text, "Number of Observations", int)

    # ---- data block: columns "y x" (or "y x1 x2 ...") as announced by the "Data:  y  x" line
    d_lo, d_hi = _span(text, "Data")
    col_line = lines[d_lo - 2].split()
    if col_line[:2] != ["Data:", "y"] or not (col_line[2:] == ["x"] or col_line[2:] == [
            f"x{i + 1}" for i in range(len(col_line) - 2)]) or len(col_line) < 3:
        raise ValueError(f"{name}: expected a 'Data: y x' or 'Data: y x1 x2 ...' column header, "
                         f"got {lines[d_lo - 2]!r}")
    n_cols = len(col_line) - 1
    rows = [[_float(t) for t in ln.split()] for ln in lines[d_lo - 1:d_hi]]
    if any(len(r) != n_cols for r in rows):
        raise ValueError(f"{name}: a data row does not have {n_cols} columns")
    data = np.array(rows, dtype=float)
    if any(ln.strip() for ln in lines[d_hi:]):
        raise ValueError(f"{name}: text after the announced data span")

    m = re.search(r"^\s*(\d+)\s+Observations\s*$", text, re.M)
    if m is None:
        raise ValueError(f"{name}: no 'N Observations' line")
    n_header = int(m.group(1))
    if not (n_header == n_obs == data.shape[0]):
        raise ValueError(f"{name}: header says {n_header} observations, certified block {n_obs}, "
                         f"data block has {data.shape[0]} rows")
    # The "Degrees of Freedom" line is kept as printed but not trusted: Rat43.dat
    # prints 9 where n - n_p = 11 (its certified residual standard deviation is
    # sqrt(RSS/11)).  Check instead that RSD**2 * (n - n_p) reproduces the RSS.
    if not math.isclose(rsd ** 2 * (n_obs - len(names)), rss, rel_tol=1e-8):
        raise ValueError(f"{name}: certified RSD**2 * (n - n_p) does not give the certified RSS")

    mm = re.search(r"^Model:.*?\n(.*?)\n\s*\n\s*\n", text, re.M | re.S)
    model_text = " ".join(mm.group(1).split()) if mm else ""

    x = data[:, 1].copy() if n_cols == 2 else data[:, 1:].copy()
    y = RESPONSE[name](data[:, 0]) if name in RESPONSE else data[:, 0].copy()
    return NistDataset(
        name=name, n=n_obs, x=x, y=y, param_names=tuple(names),
        start1=np.array(s1), start2=np.array(s2), certified=np.array(cert),
        certified_stdev=np.array(sd), certified_rss=rss, certified_rsd=rsd, dof=dof,
        model_text=model_text,
    )


def attainable_digits(d: NistDataset) -> float:
    """Digits of the RSS (and so of the standard errors, which scale with sqrt(RSS)) that double
    precision can give: log10(RSD / (eps max|y|)), the residual standard deviation in units of
    the round-off of one residual y_i - f(x_i) (capped at 11, the certified digits).

    About 2.2 for Lanczos1 (RSD 8.9e-14 on values up to 2.5), above 9 for the other 26 problems.
    """
    ulp = np.finfo(float).eps * float(np.max(np.abs(d.y)))
    return float(min(11.0, math.log10(d.certified_rsd / ulp)))


def certified_rounding(d: NistDataset) -> float:
    """A bound of ||r(b_cert) - r(b*)||: the residuals' change when the parameters move by the
    rounding of their 11-digit certified values (at most 5e-10 relative), ||J diag(5e-10 |b|)||_F
    with J = df/db at the certified values (CasADi AD)."""
    b = ca.SX.sym("b", d.n_p)
    x = ca.SX.sym("x", d.n, d.n_x)
    arg = x if d.n_x == 1 else tuple(x[:, i] for i in range(d.n_x))
    jac = ca.Function("j", [b, x], [ca.jacobian(MODELS[d.name](b, arg), b)])
    J = np.asarray(jac(d.certified, d.x))
    return float(np.linalg.norm(J * (5e-10 * np.abs(d.certified))[None, :]))


def available(data_dir: Path | str = DATA_DIR) -> list[str]:
    return sorted(p.stem for p in Path(data_dir).glob("*.dat"))


# ---------------------------------------------------------------------------- models
# Transcribed from the "Model:" section of each file (x**a is elementwise power;
# "exp[...]" in the files is exp(...)).  ENSO uses pi without defining it.
_PI = math.pi


def _gauss(b, x):
    return (b[0] * ca.exp(-b[1] * x)
            + b[2] * ca.exp(-(x - b[3]) ** 2 / b[4] ** 2)
            + b[5] * ca.exp(-(x - b[6]) ** 2 / b[7] ** 2))


def _rat_cubic(b, x):
    return (b[0] + b[1] * x + b[2] * x ** 2 + b[3] * x ** 3) / (1 + b[4] * x + b[5] * x ** 2 + b[6] * x ** 3)


#: the response the model is stated for, where it is not y itself
RESPONSE = {"Nelson": np.log}

MODELS = {
    # y = b1*(1-exp[-b2*x])
    "Misra1a": lambda b, x: b[0] * (1 - ca.exp(-b[1] * x)),
    # y = b1 * (1-(1+2*b2*x)**(-.5))
    "Misra1c": lambda b, x: b[0] * (1 - (1 + 2 * b[1] * x) ** (-0.5)),
    # y = b1*b2*x*((1+b2*x)**(-1))
    "Misra1d": lambda b, x: b[0] * b[1] * x * ((1 + b[1] * x) ** (-1)),
    # y = exp(-b1*x)/(b2+b3*x)
    "Chwirut1": lambda b, x: ca.exp(-b[0] * x) / (b[1] + b[2] * x),
    # y = b1*exp(-b2*x) + b3*exp(-b4*x) + b5*exp(-b6*x)
    "Lanczos1": lambda b, x: b[0] * ca.exp(-b[1] * x) + b[2] * ca.exp(-b[3] * x) + b[4] * ca.exp(-b[5] * x),
    "Lanczos2": lambda b, x: b[0] * ca.exp(-b[1] * x) + b[2] * ca.exp(-b[3] * x) + b[4] * ca.exp(-b[5] * x),
    # log[y] = b1 - b2*x1 * exp[-b3*x2]   (x = (x1, x2); the response is log y, see RESPONSE)
    "Nelson": lambda b, x: b[0] - b[1] * x[0] * ca.exp(-b[2] * x[1]),
    # y =  b1 - b2*x - arctan[b3/(x-b4)]/pi
    "Roszman1": lambda b, x: b[0] - b[1] * x - ca.atan(b[2] / (x - b[3])) / _PI,
    # y = b1 * (1-(1+b2*x/2)**(-2))
    "Misra1b": lambda b, x: b[0] * (1 - (1 + b[1] * x / 2) ** (-2)),
    # y = exp(-b1*x)/(b2+b3*x)
    "Chwirut2": lambda b, x: ca.exp(-b[0] * x) / (b[1] + b[2] * x),
    # y = b1*exp(-b2*x) + b3*exp(-b4*x) + b5*exp(-b6*x)
    "Lanczos3": lambda b, x: b[0] * ca.exp(-b[1] * x) + b[2] * ca.exp(-b[3] * x) + b[4] * ca.exp(-b[5] * x),
    # y = b1*exp( -b2*x ) + b3*exp( -(x-b4)**2 / b5**2 ) + b6*exp( -(x-b7)**2 / b8**2 )
    "Gauss1": _gauss,
    "Gauss2": _gauss,
    "Gauss3": _gauss,
    # y = b1*x**b2
    "DanWood": lambda b, x: b[0] * x ** b[1],
    # y = (b1 + b2*x + b3*x**2) / (1 + b4*x + b5*x**2)
    "Kirby2": lambda b, x: (b[0] + b[1] * x + b[2] * x ** 2) / (1 + b[3] * x + b[4] * x ** 2),
    # y = (b1+b2*x+b3*x**2+b4*x**3) / (1+b5*x+b6*x**2+b7*x**3)
    "Hahn1": _rat_cubic,
    "Thurber": _rat_cubic,
    # y = b1 + b2*exp[-x*b4] + b3*exp[-x*b5]
    "MGH17": lambda b, x: b[0] + b[1] * ca.exp(-x * b[3]) + b[2] * ca.exp(-x * b[4]),
    # y = b1 + b2*cos( 2*pi*x/12 ) + b3*sin( 2*pi*x/12 ) + b5*cos( 2*pi*x/b4 ) + b6*sin( 2*pi*x/b4 )
    #       + b8*cos( 2*pi*x/b7 ) + b9*sin( 2*pi*x/b7 )
    "ENSO": lambda b, x: (b[0] + b[1] * ca.cos(2 * _PI * x / 12) + b[2] * ca.sin(2 * _PI * x / 12)
                          + b[4] * ca.cos(2 * _PI * x / b[3]) + b[5] * ca.sin(2 * _PI * x / b[3])
                          + b[7] * ca.cos(2 * _PI * x / b[6]) + b[8] * ca.sin(2 * _PI * x / b[6])),
    # y = b1*(x**2+x*b2) / (x**2+x*b3+b4)
    "MGH09": lambda b, x: b[0] * (x ** 2 + x * b[1]) / (x ** 2 + x * b[2] + b[3]),
    # y = b1 * exp[b2/(x+b3)]
    "MGH10": lambda b, x: b[0] * ca.exp(b[1] / (x + b[2])),
    # y = (b1/b2) * exp[-0.5*((x-b3)/b2)**2]
    "Eckerle4": lambda b, x: (b[0] / b[1]) * ca.exp(-0.5 * ((x - b[2]) / b[1]) ** 2),
    # y = b1 / (1+exp[b2-b3*x])
    "Rat42": lambda b, x: b[0] / (1 + ca.exp(b[1] - b[2] * x)),
    # y = b1 / ((1+exp[b2-b3*x])**(1/b4))
    "Rat43": lambda b, x: b[0] / ((1 + ca.exp(b[1] - b[2] * x)) ** (1 / b[3])),
    # y = b1 * (b2+x)**(-1/b3)
    "Bennett5": lambda b, x: b[0] * (b[1] + x) ** (-1 / b[2]),
    # y = b1*(1-exp[-b2*x])
    "BoxBOD": lambda b, x: b[0] * (1 - ca.exp(-b[1] * x)),
}


def model_function(name: str, n_p: int, n: int, n_x: int = 1) -> ca.Function:
    """CasADi function ``(b[n_p], x[n, n_x]) -> y[n]`` of data set ``name`` (for checks)."""
    b = ca.SX.sym("b", n_p)
    x = ca.SX.sym("x", n, n_x)
    arg = x if n_x == 1 else tuple(x[:, i] for i in range(n_x))
    return ca.Function(name, [b, x], [MODELS[name](b, arg)])


def h_of(name: str, n_x: int = 1):
    """The model of data set ``name`` as ``h(p, q)`` for ``models.Model.explicit`` (q the inputs)."""
    fun = MODELS[name]
    if n_x == 1:
        return lambda p, q: fun(p, q[0])
    return lambda p, q: fun(p, tuple(q[i] for i in range(n_x)))
