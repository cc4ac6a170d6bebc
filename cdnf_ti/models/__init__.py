"""The looming models: every model behind one interface, registered by name.

Each model is one module with a :class:`Model` subclass decorated with
:func:`register_model`; importing this package registers the built-in ones
(``--models all`` runs them in the order imported here).
"""
from __future__ import annotations

from .base import Model, ModelBackend, NotConvergedWarning, StepResult, Sweepable, Trace
from .registry import MODELS, create_model, get_model_class, register_model

# The built-in models, imported (so registered) in this order: C-DNF, Table I's comparison models, LGMD1,
# F-LGMD ONn, then the later engine models.
# isort: off
from .cdnf import CDNF
from .sdnf import SDNF, SDNFParams
from .lgmd2 import LGMD2, LGMD2Params
from .lgmd1 import LGMD1, LGMD1Params
from .flgmd import FLGMDONn, FLGMDParams
from .olgmd import OLGMD, OLGMDParams
from .lplc2 import LPLC2, LPLC2Params
# isort: on

__all__ = ["MODELS", "Model", "ModelBackend", "Sweepable", "StepResult", "Trace", "NotConvergedWarning", "CDNF",
           "register_model", "get_model_class", "create_model",
           "LGMD2", "LGMD2Params", "LGMD1", "LGMD1Params", "SDNF", "SDNFParams", "FLGMDONn", "FLGMDParams",
           "OLGMD", "OLGMDParams", "LPLC2", "LPLC2Params"]
