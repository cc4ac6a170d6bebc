"""Stimulus generators (installed as ``cdnf_ti.stimuli``).

All generators are deterministic, yield float32 frames in [0, 1] of shape
(H, W) one at a time, and never need the whole sequence in memory.

* :mod:`.basic` - the six basic stimuli (paper Table I), with settable sizes, size law,
  speed and grey levels;
* :mod:`.grating` - a drifting square-wave grating (non-looming control);
* :mod:`.incoherent` - their incoherent versions at coherence degree c;
* :mod:`.rain` - synthetic rain on any frame stream, with SNR;
* :mod:`.io` - lossless writing (FFV1 AVI / PNG) with a JSON sidecar, and read-back.
"""
from .basic import BASIC_STIMULI, BasicStimulus, basic_stimulus, default_start_half_size
from .grating import GratingStimulus
from .incoherent import IncoherentStimulus, incoherent_stimulus, luminance_change, luminance_change_match
from .rain import RainParams, RainyFrames, snr_db

__all__ = ["BASIC_STIMULI", "BasicStimulus", "basic_stimulus", "default_start_half_size",
           "GratingStimulus", "IncoherentStimulus", "incoherent_stimulus",
           "luminance_change", "luminance_change_match", "RainParams", "RainyFrames", "snr_db"]
