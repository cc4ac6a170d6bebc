"""Throughput benchmarks of cdnf_ti (installed as ``cdnf_ti.bench``).

* :mod:`cdnf_ti.bench.peers`: the same C-DNF equations, tolerance and fixed-point
  schedule written the other ways a researcher could run them (SciPy
  ``ndimage.correlate``; dense OpenCV + NumPy; PyTorch CPU when installed).
* :mod:`cdnf_ti.bench.inputs`: benchmark inputs (basic stimuli, the development dashcam
  clips or a generated stand-in video).
* :mod:`cdnf_ti.bench.cli`: ``python -m cdnf_ti.run bench`` prints the table.
* ``bench/test_throughput.py``: pytest-benchmark tests (``pytest bench/ --benchmark-only``).
"""
