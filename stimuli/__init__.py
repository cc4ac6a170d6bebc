"""Stimulus generators (installed as ``cdnf_ti.stimuli``).

All generators are deterministic, yield float32 frames in [0, 1] of shape
(H, W) one at a time, and never need the whole sequence in memory.
"""
from .basic import BASIC_STIMULI, BasicStimulus, basic_stimulus

__all__ = ["BASIC_STIMULI", "BasicStimulus", "basic_stimulus"]
