"""Sending models (and the tasks that hold them) to other processes: by value, else rebuilt from their factory.

A model's CasADi functions pickle, but the Python functions it keeps may not with the standard
:mod:`pickle`: a factory usually defines ``y_guess`` (and its helpers) inside itself, and pickle
refuses such local functions ("Can't pickle local object 'build.<locals>.y_guess'").
:func:`dumps` therefore serialises with cloudpickle, which sends local functions and lambdas by
value (their code and the values they close over); the receiving process needs the installed
``mudoe`` packages, not the factory's module.

CasADi ``SX``/``MX`` expressions in a closure are serialised in a CasADi pickling context (with
their symbols, :func:`casadi.global_pickle_context`).  A closure may still hold something no
pickler can send (a lock, an open file, a solver object).  A model built by a factory records where it came from
(:attr:`models.Model.origin`, a :class:`ModelSource`: ``"package.module:function"`` and the
variant); :func:`dumps` then sends such models as that recipe plus the metadata changed after
building (parameters with their bounds and units, names, units of inputs and sensors), and the
receiving process calls the factory again (:func:`rebuild`).  The factory's module must then be
importable there (local worker processes share this process's ``sys.path``).
"""
from __future__ import annotations

import importlib
import pickle
from dataclasses import dataclass

from .contract import Model, ModelError, pickling_as_recipe, recipe_reducer

__all__ = ["ModelSource", "ShippingError", "dumps", "loads", "rebuild", "by_source"]

#: the attributes of a model that code may change after its factory built it (sent with the recipe)
METADATA = ("params", "inputs", "sensors", "n_y", "name", "description", "symbolic", "sensor_units",
            "input_units")


class ShippingError(ModelError):
    """A model cannot be sent to another process (neither by value nor as its factory's recipe), or its
    factory built another model there."""


@dataclass(frozen=True)
class ModelSource:
    """Where a model came from: ``factory(variant)`` with ``factory`` named ``"package.module:function"``.

    Attributes
    ----------
    factory : str          ``"package.module:function"``
    variant : str or None  the factory's argument (None: called without one)
    """

    factory: str
    variant: str | None = None

    def build(self):
        """The model ``factory(variant)`` (a :class:`models.Model`).

        Raises
        ------
        ShippingError
            The module cannot be imported, has no such function, or it does not return a Model.
        """
        mod_name, _, fn_name = self.factory.partition(":")
        try:
            fn = getattr(importlib.import_module(mod_name), fn_name)
        except (ImportError, AttributeError, ValueError) as exc:
            raise ShippingError(f"cannot rebuild the model from its factory {self.factory!r} in this process "
                                f"({type(exc).__name__}: {exc}); its module must be importable here "
                                "(on PYTHONPATH)") from None
        m = fn() if self.variant is None else fn(self.variant)
        if not isinstance(m, Model):
            raise ShippingError(f"{self.factory}({self.variant!r}) returned {type(m).__name__}, "
                                "expected a models.Model")
        return m


def by_source() -> bool:
    """True while :func:`dumps` sends models with an origin as their recipe (``Model.__reduce_ex__`` then
    returns :func:`_as_recipe`)."""
    return recipe_reducer() is not None


def _as_recipe(model):
    """The ``__reduce__`` value of a model sent as its recipe: :func:`rebuild` of its origin and metadata."""
    return (rebuild, (model.origin, {k: model.__dict__[k] for k in METADATA}))


def rebuild(source: ModelSource, metadata: dict):
    """The model of ``source`` with ``metadata`` (see :data:`METADATA`) restored: the receiving side of
    a model sent as its recipe.

    Raises
    ------
    ShippingError
        The factory built a model of another shape (states, inputs, sensors or parameter names)
        than the one sent.
    """
    m = source.build()
    want = (metadata["n_y"], tuple(metadata["inputs"]), tuple(metadata["sensors"]),
            tuple(p.name for p in metadata["params"]))
    got = (m.n_y, m.inputs, m.sensors, m.param_names)
    if got != want:
        raise ShippingError(f"{source.factory}({source.variant!r}) built another model in this process than in "
                            f"the one that sent it (states, inputs, sensors, parameters {got} instead of {want}); "
                            "a factory must build the same model every time it is called")
    m.__dict__.update(metadata)
    m.origin = source
    return m


def dumps(obj) -> bytes:
    """``obj`` as bytes for :func:`loads` in another process: by value (cloudpickle), else with every model
    that has an :attr:`~models.Model.origin` sent as its recipe (see the module docstring).

    Raises
    ------
    ShippingError
        Neither works; the message names what could not be pickled and what to do.
    """
    try:
        return _pickled(obj)
    except Exception as exc:  # noqa: BLE001 -- a __reduce__ may raise anything (CasADi raises Exception)
        first = f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"
    try:
        with pickling_as_recipe(_as_recipe):
            return _pickled(obj)
    except Exception:  # noqa: BLE001 -- as above; the first error is the one reported
        pass
    raise ShippingError(f"the model cannot be sent to worker processes ({first}); build it with a factory "
                        "\"package.module:function\" (a study's [model] name), whose model carries its origin and "
                        "is rebuilt in each worker, keep unpicklable objects (locks, open files, solvers) out of "
                        "the functions the model keeps (y_guess), or run in this process (workers = 1)")


def _pickled(obj) -> bytes:
    """cloudpickle of ``obj`` in a CasADi pickling context (SX/MX expressions serialised with their symbols)."""
    import casadi as ca
    import cloudpickle
    with ca.global_pickle_context():
        return cloudpickle.dumps(obj)


def loads(blob: bytes):
    """The object of :func:`dumps` (models sent as a recipe are rebuilt from their factory)."""
    import casadi as ca
    with ca.global_unpickle_context():
        return pickle.loads(blob)
