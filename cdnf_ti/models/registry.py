"""The model registry: every model behind one interface, looked up by name.

A model is registered by its class: a :class:`~cdnf_ti.models.base.Model` subclass decorated with
:func:`register_model`, which names its kernel module (``kernels``) and its ``render`` panels
(``panels``); :mod:`cdnf_ti.models` imports every module of its package (a program may register its own). Registered
models are what the command line's ``--models``, :func:`create_model`, ``render``, the bench and
the tests' parametrisations take; ``cdnf_ti`` exports every built-in one.
"""
from __future__ import annotations

from typing import Any, TypeVar

from .base import Model

#: Registered models by name, in registration order (``--models all`` runs them in this order).
MODELS: dict[str, type[Model]] = {}

M = TypeVar("M", bound=type[Model])


def _key(name: str) -> str:
    return name.lower().replace("-", "").replace("_", "")


def register_model(cls: M) -> M:
    """Class decorator: add a :class:`Model` subclass to :data:`MODELS` under ``cls.name``.

    Examples
    --------
    >>> @register_model                           # doctest: +SKIP
    ... class MyModel(Model):
    ...     name = "mine"

    Raises
    ------
    TypeError
        ``cls`` is not a :class:`Model` subclass.
    ValueError
        ``cls`` has no ``name``, or another model is registered under the same
        name (names compare case-insensitively, ignoring ``-`` and ``_``).
    """
    if not (isinstance(cls, type) and issubclass(cls, Model)):
        raise TypeError(f"register_model: {cls!r} is not a Model subclass")
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no registry name")
    if not all(isinstance(p, tuple) and len(p) == 2 for p in cls.panels):
        raise ValueError(f"{cls.__name__}.panels must be (field, title) pairs")
    for name, other in MODELS.items():
        same = other is cls or (other.__module__, other.__qualname__) == (cls.__module__, cls.__qualname__)
        if _key(name) == _key(cls.name) and not same:
            raise ValueError(f"model name {cls.name!r} of {cls.__qualname__} is taken by {other.__qualname__}")
    MODELS[cls.name] = cls
    return cls


def sort_models() -> None:
    """Order :data:`MODELS` by each class's ``order``, then by name (``--models all`` runs them so)."""
    ranked = sorted(MODELS.items(), key=lambda item: (item[1].order, item[0]))
    MODELS.clear()
    MODELS.update(ranked)


def get_model_class(name: str) -> type[Model]:
    """Look a model up by name (case-insensitive; ``-``/``_`` ignored)."""
    key = _key(name)
    for k, cls in MODELS.items():
        if _key(k) == key:
            return cls
    raise ValueError(f"unknown model {name!r}; available: {', '.join(MODELS)}")


def create_model(name: str, params: Any = None, *, compiler: str | None = None, **kwargs: Any) -> Model:
    """Instantiate a registered model: ``create_model("cdnf", backend="numpy")``.

    ``compiler`` ("quadrants" or "taichi") names the process's kernel compiler
    (:meth:`cdnf_ti.backends.Engine.select_compiler`); ``None`` keeps the default.
    """
    if compiler is not None and kwargs.get("backend", "taichi") == "taichi":
        Model._engine().select_compiler(compiler)
    return get_model_class(name)(params, **kwargs)
