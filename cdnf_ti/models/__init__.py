"""Model registry: every model behind one interface, looked up by name."""
from __future__ import annotations

from typing import Any

from .base import Model, NotConvergedWarning, StepResult, Trace
from .cdnf import CDNF
from .flgmd import FLGMDONn, FLGMDParams
from .lgmd1 import LGMD1, LGMD1Params
from .lgmd2 import LGMD2, LGMD2Params
from .sdnf import SDNF, SDNFParams

MODELS: dict[str, type[Model]] = {}


def register_model(cls: type[Model]) -> type[Model]:
    """Add a :class:`Model` subclass to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no registry name")
    MODELS[cls.name] = cls
    return cls


def get_model_class(name: str) -> type[Model]:
    """Look a model up by name (case-insensitive; ``-``/``_`` ignored)."""
    key = name.lower().replace("-", "").replace("_", "")
    for k, cls in MODELS.items():
        if k.replace("_", "").replace("-", "") == key:
            return cls
    raise ValueError(f"unknown model {name!r}; available: {', '.join(MODELS)}")


def create_model(name: str, params: Any = None, *, compiler: str | None = None, **kwargs: Any) -> Model:
    """Instantiate a registered model: ``create_model("cdnf", backend="numpy")``.

    ``compiler`` ("quadrants" or "taichi") names the process's kernel compiler
    (:func:`cdnf_ti.taichi_runtime.select_compiler`); ``None`` keeps the default.
    """
    if compiler is not None and kwargs.get("backend", "taichi") == "taichi":
        from ..taichi_runtime import select_compiler

        select_compiler(compiler)
    return get_model_class(name)(params, **kwargs)


register_model(CDNF)
register_model(SDNF)
register_model(LGMD2)
register_model(FLGMDONn)
register_model(LGMD1)

__all__ = ["MODELS", "Model", "StepResult", "Trace", "NotConvergedWarning", "CDNF",
           "register_model", "get_model_class", "create_model",
           "LGMD2", "LGMD2Params", "LGMD1", "LGMD1Params", "SDNF", "SDNFParams", "FLGMDONn", "FLGMDParams"]
