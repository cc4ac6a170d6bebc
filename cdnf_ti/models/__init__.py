"""The looming models: every model behind one interface, registered by name.

Each model is one module of this package with a :class:`Model` subclass decorated with
:func:`register_model`. Importing the package imports every such module (so a new model is a new
file here, and nothing else changes) and exports each registered class and its parameters' class.
``--models all`` runs them by their ``order`` (C-DNF first, then Table I's comparison models, then the
later models by name).
"""
from __future__ import annotations

import importlib
import pkgutil

from .base import Model, ModelBackend, NotConvergedWarning, StepResult, Sweepable, Trace
from .registry import MODELS, create_model, get_model_class, register_model, sort_models

#: Modules of this package that hold no model.
_NOT_MODELS = {"base", "reference_backend", "registry"}

for _info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
    if _info.name not in _NOT_MODELS and not _info.name.startswith("_"):
        importlib.import_module(f"{__name__}.{_info.name}")
sort_models()

#: Every built-in model class and its parameters' class, by class name (``from cdnf_ti.models import SDNF``).
_EXPORTS = {c.__name__: c for m in MODELS.values() for c in (m, m.params_type) if c is not object}
globals().update(_EXPORTS)

__all__ = ["MODELS", "Model", "ModelBackend", "Sweepable", "StepResult", "Trace", "NotConvergedWarning",
           "register_model", "get_model_class", "create_model", *sorted(_EXPORTS)]
