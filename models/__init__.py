"""Model contract and model library."""
from .contract import Model, ModelError, Parameter

__all__ = ["Model", "ModelError", "Parameter"]
