"""The engine side of the models: compiled backends, built by a factory outside ``cdnf_ti.models``.

A model (:class:`~cdnf_ti.models.base.Model`) states its equations' control flow and
owns its scalar state; its per-pixel state and the kernels that update it live in a
backend made here, by :data:`ENGINE` (installed as ``Model.engine`` by the ``cdnf_ti``
package). Importing this package loads no compiler: the runtime starts when the first
model with the ``"taichi"`` backend is made, and the kernels are built then
(:func:`cdnf_ti.taichi_runtime.kernels`).

Every model names its kernel module (``Model.kernels``) and runs on the one generic backend,
:class:`~cdnf_ti.backends.engine.Backend`.
"""
from __future__ import annotations

from typing import Any

from .. import taichi_runtime
from .engine import Backend


class Engine:
    """What :class:`~cdnf_ti.models.base.Model` asks of the compiler layer (``Model.engine``)."""

    @staticmethod
    def select_compiler(compiler: str) -> None:
        """Name this process's kernel compiler before its runtime starts
        (:func:`~cdnf_ti.taichi_runtime.select_compiler`)."""
        taichi_runtime.select_compiler(compiler)

    @staticmethod
    def start(arch: str) -> str:
        """Start the runtime on ``arch`` (once per process); returns the arch in use."""
        return taichi_runtime.ensure_taichi(arch)

    @staticmethod
    def compile_count() -> int:
        """Kernels compiled (or loaded from the compile cache) in this process so far
        (:func:`~cdnf_ti.taichi_runtime.compile_count`)."""
        return taichi_runtime.compile_count()

    @staticmethod
    def compiling(label: str) -> Any:
        """A context of steps that may compile kernels for ``label``: a one-line notice on a cold cache
        (:class:`~cdnf_ti.taichi_runtime.compiling`)."""
        return taichi_runtime.compiling(label)

    @staticmethod
    def backend(model: Any, shape: tuple[int, int]) -> Any:
        """The compiled backend of ``model`` for frames of ``shape`` (H, W)."""
        if getattr(model, "kernels", None) is None:
            raise NotImplementedError(f"{type(model).__name__} names no kernel module (Model.kernels)")
        arch = taichi_runtime.ensure_taichi(model.arch)
        return Backend(model, tuple(shape), arch)


ENGINE = Engine()
