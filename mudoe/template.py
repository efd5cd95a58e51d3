"""``mudoe init``: a commented study config template for a user's model factory.

With ``--model package.module:function`` the factory is called once (variant ``"default"``) and
the template of its kind of study (:meth:`mudoe.kind.base.StudyKind.template_text`: a static model's
set points and wide CSV, or an ODE/DAE model's [dynamic] section) lists its parameters (start value
from the parameter's scale, unit), inputs and sensors (with units); without it the template has
placeholders to fill in.  An existing file is never overwritten.
"""
from __future__ import annotations

from pathlib import Path

from models.fileio import create_text

from .checks import call_factory
from .config import ConfigError
from .kind import kind_of
from .kind.static import template_text
from .study_base import load_factory

__all__ = ["template_text", "write_template"]


def write_template(path, model_name: str | None = None) -> Path:
    """Write :func:`template_text` to ``path`` (a new file).

    Raises
    ------
    ConfigError
        ``path`` exists (never overwritten), or the factory cannot be loaded or returns no Model.
    """
    path = Path(path)
    if path.exists():
        raise ConfigError(f"{path}: exists; mudoe init never overwrites a file, choose a new name")
    if model_name is None:
        text = template_text()
    else:
        factory = load_factory(model_name, "--model")
        model = call_factory(factory, model_name, "default", lambda msg: ConfigError(f"--model: {msg}"))
        kind = kind_of(model)
        if kind is None:
            raise ConfigError(f"--model: {model_name}('default') returned {type(model).__name__}, expected a "
                              "models.Model")
        text = kind.template_text(model, model_name)
    if not path.parent.is_dir():
        raise ConfigError(f"{path}: the folder {path.parent} does not exist; create it or choose another path")
    try:
        return create_text(path, text)
    except FileExistsError:
        raise ConfigError(f"{path}: exists (written meanwhile by another process); mudoe init never overwrites "
                          "a file, choose a new name") from None
