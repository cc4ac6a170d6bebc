"""The engine's kernels (installed as ``cdnf_ti.kernels``): the per-pixel work of every model.

Each module defines its kernels in a factory, ``build(ti, lanes)``, so importing it loads no
compiler; :func:`cdnf_ti.taichi_runtime.kernels` builds them once the compiler and arch are
chosen. See ``docs/ARCHITECTURE.md``.
"""
