"""Model contract and model library."""
from .contract import Model, ModelError, Parameter
from . import collocation  # noqa: F401  (registers the function behind DynamicModel.collocate)
from .mechanism import (Bar, Beam, Drive, Joint, Load, Mass, MechanismError, Mechanism, MechParameter, RigidBody,
                        Support, build_model, load_toml)
from .press import PRESS_SENSORS, press_mechanism, press_model

__all__ = ["Model", "ModelError", "Parameter", "Bar", "Beam", "Drive", "Joint", "Load", "Mass", "MechanismError",
           "Mechanism", "MechParameter", "RigidBody", "Support", "build_model", "load_toml", "PRESS_SENSORS",
           "press_mechanism", "press_model"]
