"""Taichi kernels (installed as ``cdnf_ti.kernels``): the per-pixel work of every model.

Import these modules only after :func:`cdnf_ti.taichi_runtime.ensure_taichi`.
"""
